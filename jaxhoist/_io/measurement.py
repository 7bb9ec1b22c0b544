"""Measured time series for parameter identification: read, validate, write (CSV + JSON side file).

A measurement file is a CSV table with a time column `t` and one column per measured signal, each header
cell carrying its unit in brackets:

    t [s],position_x [m],position_y [m],position_z [m],rope_tension [kN]
    0.00,1.0003,2.4987,0.9980,0.012
    0.02,1.0012,2.5021,1.0011,3.871
    ...

Units may instead (or also, if they agree) be given in a side file with the same stem, `NAME.json`:

    {"units": {"t": "s", "position_x": "m", "rope_tension": "kN"},
     "noise": {"position_x": 0.005, "rope_tension": "1%"}}

`noise` (optional) gives each signal's measurement noise as a standard deviation in the column's unit, or as
a percentage of the signal's root-mean-square value ("1%"). Values are converted to SI on reading.

Signal names follow the fields of `jaxhoist.Trajectory` (see `SIGNALS`): `position_x`, `euler_phi`,
`corners_D_z`, `normal_forces_E`, `rope_tension`, ... Every error is a `MeasurementError` naming the file,
the column and the line, and is raised on the host, before anything is compiled.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import re
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from .._errors import ScenarioError
from .signals import SIGNALS as SIGNALS
from .signals import UNITS as UNITS
from .signals import MeasurementError as MeasurementError
from .signals import SignalSpec as SignalSpec
from .signals import check_signal_names as check_signal_names
from .signals import hint
from .signals import signal_groups as signal_groups
from .signals import unit_factor as unit_factor
from .validate import parse_number, read_text, whole_number

# ------------------------------------------------------------------------------------------ object


@dataclasses.dataclass(frozen=True)
class Measurement:
    """Measured signals on one time grid, in SI units (numpy arrays, host side only).

    - `t`: sample times [s], strictly increasing, shape (n,).
    - `signals`: name -> values at `t` in the SI unit of `SIGNALS[name]`, each shape (n,).
    - `noise`: name -> noise standard deviation [SI unit of the signal] for the signals where it is known.
    - `source`: where the data came from (a file path or a label), used in error messages.
    """

    t: np.ndarray
    signals: dict[str, np.ndarray]
    noise: dict[str, float] = dataclasses.field(default_factory=dict)
    source: str = "<measurement>"

    def __post_init__(self):
        object.__setattr__(self, "t", np.asarray(self.t, dtype=np.float64))
        object.__setattr__(
            self, "signals", {k: np.asarray(v, dtype=np.float64) for k, v in self.signals.items()}
        )
        object.__setattr__(self, "noise", {k: float(v) for k, v in self.noise.items()})
        self.validate()

    @property
    def names(self) -> list[str]:
        return list(self.signals)

    def units(self) -> dict[str, str]:
        """name -> SI unit (including `t`)."""
        return {"t": "s", **{k: SIGNALS[k].unit for k in self.signals}}

    def validate(self) -> None:
        """Raise `MeasurementError` naming the problem: shapes, unknown names, NaN/inf, unsorted or
        duplicate times, non-positive noise."""
        src, t = self.source, self.t
        if t.ndim != 1 or t.size < 2:
            raise MeasurementError(
                f"{src}: the time column t must hold at least 2 samples, got shape {t.shape}"
            )
        if not self.signals:
            raise MeasurementError(f"{src}: no signal columns besides t")
        check_signal_names(self.signals, src)
        _check_finite(src, "t", t, None)
        _check_times(src, t, None)
        for name, v in self.signals.items():
            if v.shape != t.shape:
                raise MeasurementError(
                    f"{src}: signal {name!r} has shape {v.shape}, the time column {t.shape}"
                )
            _check_finite(src, name, v, None)
        for name, s in self.noise.items():
            if name not in self.signals:
                raise MeasurementError(
                    f"{src}: noise given for {name!r}, which is not a measured signal (signals: {self.names})"
                )
            if not (np.isfinite(s) and s > 0):
                raise MeasurementError(
                    f"{src}: noise of {name!r} must be a positive standard deviation "
                    f"[{SIGNALS[name].unit}], got {s}"
                )

    def check_span(self, t1: float) -> None:
        """Raise `MeasurementError` unless every sample time lies in the simulated span [0, t1] [s]."""
        t = self.t
        bad = np.flatnonzero((t < 0.0) | (t > t1 * (1 + 1e-12)))
        if bad.size:
            raise MeasurementError(
                f"{self.source}: {bad.size} sample time(s) outside the simulated span [0, {t1:g}] s, first "
                f"t = {t[bad[0]]:g} s (sample {bad[0]}); shorten the measurement or simulate longer (t1)"
            )

    def select(self, names: Iterable[str]) -> Measurement:
        """A measurement with only the named signals (group names such as `position` allowed)."""
        names = list(names)
        if not names:
            raise MeasurementError(
                f"{self.source}: the signal selection is empty; choose from the measured {self.names}"
            )
        check_signal_names(names, f"{self.source}: signal selection", groups=True)
        chosen: list[str] = []
        for n in names:
            hits = [s for s in signal_groups(n) if s in self.signals]
            if not hits:
                raise MeasurementError(
                    f"{self.source}: {n!r} selects no measured signal (measured: {self.names})"
                )
            chosen += [s for s in hits if s not in chosen]
        return Measurement(
            self.t,
            {s: self.signals[s] for s in chosen},
            {s: v for s, v in self.noise.items() if s in chosen},
            self.source,
        )


def _check_finite(src: str, name: str, v: np.ndarray, lines: np.ndarray | None) -> None:
    bad = np.flatnonzero(~np.isfinite(v))
    if bad.size:
        where = f"line {int(lines[bad[0]])}" if lines is not None else f"sample {bad[0]}"
        kind = "NaN" if np.isnan(v[bad[0]]) else "an infinite value"
        raise MeasurementError(
            f"{src}: column {name!r} holds {kind} at {where} "
            f"({bad.size} non-finite value(s) in that column); drop or fill those samples"
        )


def _check_times(src: str, t: np.ndarray, lines: np.ndarray | None) -> None:
    d = np.diff(t)

    def where(i):
        return f"line {int(lines[i])}" if lines is not None else f"sample {i}"

    dup = np.flatnonzero(d == 0)
    if dup.size:
        i = dup[0]
        raise MeasurementError(
            f"{src}: duplicate time t = {t[i]:g} s at {where(i)} and {where(i + 1)}; "
            f"every sample needs its own time"
        )
    back = np.flatnonzero(d < 0)
    if back.size:
        i = back[0]
        raise MeasurementError(
            f"{src}: times are not sorted: t = {t[i + 1]:g} s at {where(i + 1)} comes after "
            f"t = {t[i]:g} s at {where(i)}; sort the rows by time"
        )


# ------------------------------------------------------------------------------------------ reading

_HEADER = re.compile(r"^\s*([^\[\]]*?)\s*(?:\[\s*([^\]]*?)\s*\])?\s*$")


def _side_json(path: Path, units_file: str | Path | None) -> tuple[dict, str | None]:
    side = Path(units_file) if units_file is not None else path.with_suffix(".json")
    if not side.exists():
        if units_file is not None:
            raise MeasurementError(f"{side}: side file not found")
        return {}, None
    try:
        data = json.loads(_text(side, "units side file"))
    except json.JSONDecodeError as e:
        raise MeasurementError(f"{side}: not valid JSON: {e}") from None
    except RecursionError:
        raise MeasurementError(f"{side}: not valid JSON: nested too deeply") from None
    if not isinstance(data, dict):
        raise MeasurementError(f"{side}: expected a JSON object with keys 'units' and/or 'noise'")
    if units_file is None and str(data.get("format", "")).startswith("jaxhoist-"):
        # `jaxhoist simulate` writes trajectory.csv next to trajectory.json, the sidecar of trajectory.npz:
        # not a measurement side file (the CSV header carries every unit), so it is not read as one.
        return {}, None
    for key in data:
        if key not in ("units", "noise", "description", "metadata"):
            raise MeasurementError(
                f"{side}: unknown key {key!r}{hint(key, ['units', 'noise'])}; "
                f"expected 'units', 'noise', 'description', 'metadata'"
            )
    for key in ("units", "noise"):
        if key in data and not isinstance(data[key], dict):
            raise MeasurementError(f"{side}: {key!r} must map column names to values")
    return data, str(side)


def _text(path: Path, what: str) -> str:
    """The UTF-8 text of a file (a UTF-8 byte-order mark dropped), or a `MeasurementError` naming it."""
    try:
        return read_text(path, what)
    except MeasurementError:
        raise
    except ScenarioError as e:
        raise MeasurementError(str(e)) from None


def _noise_value(raw, name: str, factor: float, values: np.ndarray, where: str) -> float:
    if isinstance(raw, str):
        s = raw.strip()
        if s.endswith("%"):
            try:
                pct = float(s[:-1])
            except ValueError:
                raise MeasurementError(
                    f"{where}: noise of {name!r} must be a number or 'x%', got {raw!r}"
                ) from None
            rms = float(np.sqrt(np.mean(values**2)))
            if not (np.isfinite(pct) and pct > 0) or rms == 0.0:
                raise MeasurementError(
                    f"{where}: relative noise of {name!r} needs a positive percentage and a "
                    f"signal that is not all zero, got {raw!r}"
                )
            return pct / 100.0 * rms
        try:
            raw = float(s)
        except ValueError:
            raise MeasurementError(
                f"{where}: noise of {name!r} must be a number or 'x%', got {raw!r}"
            ) from None
    if isinstance(raw, bool) or not isinstance(raw, int | float):
        raise MeasurementError(f"{where}: noise of {name!r} must be a number or 'x%', got {raw!r}")
    return float(raw) * factor


def read_measurement(
    path: str | Path, *, units_file: str | Path | None = None, t1: float | None = None
) -> Measurement:
    """Read and validate a measurement CSV (and its JSON side file `NAME.json` if present).

    **Arguments**
    - `path`: the CSV file; header `t [s],<signal> [<unit>],...`.
    - `units_file`: a JSON side file other than `NAME.json` (keys `units`, `noise`).
    - `t1`: if given, the end of the simulated span [s]: every time must lie in [0, t1].

    **Returns** a `Measurement` in SI units.

    **Raises** `MeasurementError` naming the file, the column and the line for: a missing file or time
    column, unknown signal names (with a did-you-mean hint), missing or wrong units, text or NaN/inf values,
    ragged rows, unsorted or duplicate times, times outside [0, t1], bad noise entries.
    """
    path = Path(path)
    src = str(path)
    if not path.exists():
        raise MeasurementError(f"{src}: measurement file not found")
    text = _text(path, "measurement file")
    side, side_src = _side_json(path, units_file)
    try:
        rows = [(i + 1, r) for i, r in enumerate(csv.reader(io.StringIO(text, newline="")))]
    except csv.Error as e:
        raise MeasurementError(f"{src}: not a readable CSV table: {e}") from None
    rows = [
        (n, r)
        for n, r in rows
        if r and not (len(r) == 1 and not r[0].strip()) and not r[0].lstrip().startswith("#")
    ]
    if not rows:
        raise MeasurementError(f"{src}: the file is empty")
    header_line, header = rows[0]
    names, header_units = [], []
    for cell in header:
        m = _HEADER.match(cell)
        if m is None or not m.group(1):
            raise MeasurementError(
                f"{src}: header cell {cell!r} is not of the form 'name [unit]' (line {header_line})"
            )
        names.append(m.group(1))
        header_units.append(m.group(2))
    seen = set()
    for n in names:
        if n in seen:
            raise MeasurementError(f"{src}: column {n!r} appears twice in the header")
        seen.add(n)
    if "t" not in names:
        raise MeasurementError(
            f"{src}: no time column 't' in the header {names}{hint('t', [n for n in names if n])}"
            f"; the first column should read 't [s]'"
        )
    check_signal_names([n for n in names if n != "t"], src)
    side_units = side.get("units", {})
    for key in side_units:
        if key not in names:
            raise MeasurementError(
                f"{side_src}: units given for {key!r}, which is not a column of {src} {hint(key, names)}"
            )
    factors = {}
    for n, hu in zip(names, header_units, strict=True):
        su = side_units.get(n)
        if su is not None and not isinstance(su, str):
            raise MeasurementError(f"{side_src}: unit of {n!r} must be a string, got {su!r}")
        if hu and su and hu.strip() != su.strip():
            raise MeasurementError(
                f"{src}: column {n!r} has unit {hu!r} in the header but {su!r} in {side_src}"
            )
        unit = hu or su
        si = "s" if n == "t" else SIGNALS[n].unit
        if not unit:
            raise MeasurementError(
                f"{src}: column {n!r} has no unit: write '{n} [{si}]' in the header, or give "
                f"it in the side file {path.with_suffix('.json').name} under 'units'"
            )
        factors[n] = unit_factor(unit, si, f"{src}: column {n!r}")
    body = rows[1:]
    if len(body) < 2:
        raise MeasurementError(f"{src}: needs at least 2 data rows, got {len(body)}")
    data = np.empty((len(body), len(names)))
    lines = np.array([n for n, _ in body])
    for r, (line, row) in enumerate(body):
        if len(row) != len(names):
            raise MeasurementError(
                f"{src}: line {line} has {len(row)} values, the header has {len(names)} columns"
            )
        for c, cell in enumerate(row):
            s = cell.strip()
            try:
                data[r, c] = parse_number(s, "cell") if s else np.nan
            except ScenarioError:
                raise MeasurementError(
                    f"{src}: line {line}, column {names[c]!r}: {cell[:40]!r} is not a number"
                    + (" (underscores are not allowed in numbers)" if "_" in cell else "")
                ) from None
    cols = {n: data[:, i] * factors[n] for i, n in enumerate(names)}
    for n in names:
        _check_finite(src, n, data[:, names.index(n)], lines)
    t = cols.pop("t")
    _check_times(src, t, lines)
    noise = {}
    for n, raw in side.get("noise", {}).items():
        if n not in cols:
            raise MeasurementError(
                f"{side_src}: noise given for {n!r}, which is not a signal column of {src}"
                f"{hint(n, list(cols))}"
            )
        noise[n] = _noise_value(raw, n, factors[n], cols[n], side_src)  # pyright: ignore[reportArgumentType]  # where is None only for noise given on the command line, which _noise_value accepts
        if not (np.isfinite(noise[n]) and noise[n] > 0):
            raise MeasurementError(f"{side_src}: noise of {n!r} must be positive, got {raw!r}")
    m = Measurement(t, cols, noise, src)
    if t1 is not None:
        m.check_span(t1)
    return m


# ------------------------------------------------------------------------------------------ writing


def write_measurement(
    path: str | Path,
    measurement: Measurement,
    *,
    units: Mapping[str, str] | None = None,
    side_file: bool = True,
    description: str | None = None,
    digits: int = 12,
) -> Path:
    """Write a measurement as CSV (units in the header) and, with `side_file`, `NAME.json` holding the
    units and the noise levels (standard deviations in the column units).

    - `units`: column -> unit to write in (e.g. {"rope_tension": "kN"}); default SI.
    - `digits`: significant digits per value (1 to 17); refused where the times written with them would
      repeat, so that the file always reads back.

    **Returns** the CSV path.
    """
    path = Path(path)
    if not whole_number(digits) or not 1 <= digits <= 17:
        raise MeasurementError(
            f"write_measurement({path}): digits must be a whole number 1 to 17, got {digits!r}"
        )
    units = dict(units or {})
    all_units = measurement.units()
    check_signal_names([k for k in units if k != "t"], f"write_measurement({path}): units")
    cols = {"t": measurement.t, **measurement.signals}
    header, scaled, used = [], [], {}
    for name, values in cols.items():
        unit = units.get(name, all_units[name])
        f = unit_factor(unit, all_units[name], f"write_measurement({path}): column {name!r}")
        header.append(f"{name} [{unit}]")
        scaled.append(values / f)
        used[name] = (unit, f)
    rows = [[f"{x:.{digits}g}" for x in row] for row in np.stack(scaled, axis=1)]
    written = np.array([float(row[0]) for row in rows])
    if np.any(np.diff(written) <= 0):  # the file could not be read back: its times would repeat
        t_unit = used["t"][0]
        raise MeasurementError(
            f"write_measurement({path}): digits = {digits} is too few to keep the sample times apart "
            f"(written, {written[0]:g} to {written[-1]:g} {t_unit} would repeat or go back): give more digits"
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    if side_file:
        side = {
            "units": {n: u for n, (u, _) in used.items()},
            "noise": {n: s / used[n][1] for n, s in measurement.noise.items()},
        }
        if description:
            side["description"] = description
        path.with_suffix(".json").write_text(json.dumps(side, indent=2) + "\n")
    return path
