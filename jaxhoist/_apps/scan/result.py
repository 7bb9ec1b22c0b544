"""`ScanResult`: the labelled dataset a scan returns (parameter coordinates x observables, per-member
status, optional time histories) and its files: `save`/`load` (npz + JSON sidecar), `to_netcdf`,
`to_xarray`."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ..._io.scan_store import FORMAT, json_default
from ..._numerics.batch import ScanStatus


class ScanResult:
    """A labelled scan dataset: parameter coordinates × observables (× optional time histories).

    - `params`: the swept parameter paths, in order; `mode`: "sweep", "grid" or "points".
    - `coords`: path -> values. For a grid, the axis values (the data have one axis per parameter);
      otherwise the value of that parameter for each member (one data axis).
    - `shape`: the shape of the member axes.
    - `data`: observable name -> array of shape `shape + observable shape` (NaN where a member failed).
    - `components`: observable name -> labels of its last axis (or None).
    - `status`: `ScanStatus` codes, shape `shape`; `reasons`: flat member index -> message for failures.
    - `num_accepted_steps`, `num_rejected_steps`: solver steps per member.
    - `ts`, `histories`: saved times [s] and name -> array of shape `shape + (n_t, ...)` if requested.
    - `units`: name -> SI unit for every parameter, observable and history; `descriptions` likewise.
    - `attrs`: JSON-able metadata (scenario, t1, solver options, lanes, devices, timings, the accuracy
      report `accuracy`, and `group_program`: how the compiled group program was had: "compiled",
      "loaded" from the persistent compilation cache's folder, "reused" from this process, or None where
      every chunk was read back from `out_dir`).
    """

    def __init__(
        self,
        *,
        params,
        mode,
        coords,
        shape,
        data,
        components,
        status,
        reasons,
        num_accepted_steps,
        num_rejected_steps,
        ts,
        histories,
        units,
        descriptions,
        attrs,
    ):
        self.params = tuple(params)
        self.mode = mode
        self.coords = {k: np.asarray(v) for k, v in coords.items()}
        self.shape = tuple(shape)
        self.data = {k: np.asarray(v) for k, v in data.items()}
        self.components = dict(components)
        self.status = np.asarray(status)
        self.reasons = {int(k): str(v) for k, v in reasons.items()}
        self.num_accepted_steps = np.asarray(num_accepted_steps)
        self.num_rejected_steps = np.asarray(num_rejected_steps)
        self.ts = None if ts is None else np.asarray(ts)
        self.histories = {k: np.asarray(v) for k, v in (histories or {}).items()}
        self.units = dict(units)
        self.descriptions = dict(descriptions)
        self.attrs = dict(attrs)

    # ---- access
    def __getitem__(self, name: str) -> np.ndarray:
        if name in self.data:
            return self.data[name]
        if name in self.histories:
            return self.histories[name]
        if name in self.params:
            return self.values(name)
        raise KeyError(
            f"{name!r}: not an observable, history or parameter of this scan "
            f"(observables {list(self.data)}, histories {list(self.histories)})"
        )

    def values(self, path: str) -> np.ndarray:
        """The value of parameter `path` for every member, shape `shape`."""
        if self.mode != "grid":
            return self.coords[path]
        axes = [self.coords[p] for p in self.params]
        return np.meshgrid(*axes, indexing="ij")[self.params.index(path)]

    @property
    def ok(self) -> np.ndarray:
        """True where the member was solved and every observable is defined."""
        return self.status == ScanStatus.OK

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    @property
    def accuracy(self) -> dict[str, Any] | None:
        """The scan's report of its own accuracy (`AccuracyCheck`), or None where it was not checked: the
        members re-solved at a tighter tolerance (`members`, flat `indices`; `chosen`: those with the most
        solver steps, those drawn at random, those re-solved in further rounds), the `reference` options, and
        per observable (`observables[name]`) and kept history (`histories[name]`) the `median` and `max`
        difference ([m] for lengths, relative for the others), the members `over_target` and the `target`; in
        all `over_target` and `suggest` (the option that gives more accuracy, where members are over the
        target). Also in `scan.json` under `attrs.accuracy`."""
        return self.attrs.get("accuracy")

    def reason(self, i) -> str:
        """Why member i (flat index, or an index tuple for a grid) failed ("ok" if it did not)."""
        flat = int(np.ravel_multi_index(i, self.shape)) if isinstance(i, tuple) else int(i)
        code = ScanStatus(int(self.status.ravel()[flat]))
        return self.reasons.get(flat, code.message)

    def status_counts(self) -> dict[str, int]:
        """How many members ended with each `ScanStatus` that occurs, by name (`{"ok": 97,
        "energy_balance": 2, "max_steps": 1}`): failures of each kind counted apart."""
        codes, counts = np.unique(self.status.ravel(), return_counts=True)
        return {ScanStatus(int(c)).name.lower(): int(n) for c, n in zip(codes, counts, strict=True)}

    def failures(self) -> list[dict[str, Any]]:
        """One dict per failed member: flat index, parameter values, status name and reason."""
        out = []
        for flat in np.flatnonzero(self.status.ravel() != ScanStatus.OK):
            out.append(
                {
                    "index": int(flat),
                    "params": {p: float(self.values(p).ravel()[flat]) for p in self.params},
                    "status": ScanStatus(int(self.status.ravel()[flat])).name.lower(),
                    "reason": self.reason(int(flat)),
                }
            )
        return out

    def __repr__(self) -> str:
        n_fail = int(np.sum(~self.ok))
        return (
            f"ScanResult(mode={self.mode!r}, params={list(self.params)}, shape={self.shape}, "
            f"observables={list(self.data)}, histories={list(self.histories)}, failed={n_fail})"
        )

    # ---- files
    def _arrays(self) -> tuple[dict[str, np.ndarray], dict[str, tuple[str, str]]]:
        arrays: dict[str, np.ndarray] = {}
        units: dict[str, tuple[str, str]] = {}
        for p in self.params:
            arrays[f"coord:{p}"] = self.coords[p]
            units[f"coord:{p}"] = (self.units.get(p, "?"), f"swept parameter {p}")
        for k, v in self.data.items():
            arrays[f"obs:{k}"] = v
            units[f"obs:{k}"] = (self.units.get(k, "?"), self.descriptions.get(k, ""))
        for k, v in self.histories.items():
            arrays[f"hist:{k}"] = v
            units[f"hist:{k}"] = (self.units.get(k, "?"), f"time history of {k} at the saved times ts")
        arrays["status"] = self.status
        units["status"] = ("-", "ScanStatus: " + ", ".join(f"{s.value} {s.name.lower()}" for s in ScanStatus))
        arrays["num_accepted_steps"] = self.num_accepted_steps
        units["num_accepted_steps"] = ("-", "accepted solver steps")
        arrays["num_rejected_steps"] = self.num_rejected_steps
        units["num_rejected_steps"] = ("-", "rejected solver steps")
        if self.ts is not None:
            arrays["ts"] = self.ts
            units["ts"] = ("s", "saved times")
        return arrays, units

    def save(self, path: str | Path) -> tuple[Path, Path]:
        """Write `<stem>.npz` (plain arrays: `coord:<path>`, `obs:<name>`, `hist:<name>`, `status`, ...) and a
        self-describing `<stem>.json` sidecar (units, meanings, shapes, parameters, failures, metadata)."""
        from ..._io.results import save_arrays

        arrays, units = self._arrays()
        meta = {
            "scan": {
                "mode": self.mode,
                "params": list(self.params),
                "shape": list(self.shape),
                "components": {k: (list(v) if v else None) for k, v in self.components.items()},
                "reasons": {str(k): v for k, v in self.reasons.items()},
                "status_counts": self.status_counts(),
                "units": self.units,
                "descriptions": self.descriptions,
            },
            "attrs": self.attrs,
        }
        return save_arrays(
            path, arrays, units, json.loads(json.dumps(meta, default=json_default)), kind=FORMAT
        )

    @classmethod
    def load(cls, path: str | Path) -> ScanResult:
        """Read a result written by `save` (give the `.npz`, the `.json` or the stem)."""
        from ..._io.results import load_result

        arrays, meta = load_result(path)
        s = meta["scan"]
        return cls(
            params=s["params"],
            mode=s["mode"],
            coords={p: arrays[f"coord:{p}"] for p in s["params"]},
            shape=tuple(s["shape"]),
            data={k[4:]: v for k, v in arrays.items() if k.startswith("obs:")},
            components={k: (tuple(v) if v else None) for k, v in s["components"].items()},
            status=arrays["status"],
            reasons=s["reasons"],
            num_accepted_steps=arrays["num_accepted_steps"],
            num_rejected_steps=arrays["num_rejected_steps"],
            ts=arrays.get("ts"),
            histories={k[5:]: v for k, v in arrays.items() if k.startswith("hist:")},
            units=s["units"],
            descriptions=s["descriptions"],
            attrs=meta.get("attrs", {}),
        )

    def axes(self, name: str) -> list[tuple[str, int, tuple[str, ...] | None]]:
        """The trailing (per-member) axes of observable `name`: (dimension name, length, labels or None).
        A vector observable's first axis is `<name>_component` (labelled by its components); a sensitivity
        `d_<name>` has the axes of `<name>` and then `parameter` (labelled by the swept paths)."""
        v = self.data[name]
        trailing = v.shape[len(self.shape) :]
        if name.startswith("d_") and name[2:] in self.data:
            return [*self.axes(name[2:]), ("parameter", trailing[-1], tuple(self.params))]
        out = []
        for i, n in enumerate(trailing):
            labels = self.components.get(name) if i == 0 else None
            d = f"{name}_component" if i == 0 else f"{name}_dim{i}"
            out.append((d, n, tuple(labels) if labels and len(labels) == n else None))
        return out

    def _layout(self):
        """The labelled-dataset view shared by `to_xarray` and `to_netcdf`: (dimension sizes, coordinates,
        data variables), each variable as (name, dimension names, values, attributes); text coordinates
        (component labels) are lists of str."""
        dims: dict[str, int] = {}
        member_dims = list(self.params) if self.mode == "grid" else ["member"]
        for d, n in zip(member_dims, self.shape, strict=True):
            dims[d] = n
        coords = []
        for p in self.params:
            cdims = (p,) if self.mode == "grid" else ("member",)
            attrs = {"units": self.units.get(p, "?"), "description": self.descriptions.get(p, "")}
            coords.append((p, cdims, self.coords[p], attrs))
        if self.ts is not None:
            dims["t"] = self.ts.size
            coords.append(("t", ("t",), self.ts, {"units": "s", "description": "saved times"}))
        variables = []
        labelled: set[str] = set()
        for k, v in self.data.items():
            extra = []
            for d, n, labels in self.axes(k):
                dims[d], extra = n, [*extra, d]
                if labels is not None and d not in labelled:
                    labelled.add(d)
                    coords.append((d, (d,), list(labels), {}))
            attrs = {"units": self.units.get(k, "?"), "description": self.descriptions.get(k, "")}
            variables.append((k, (*member_dims, *extra), v, attrs))
        for k, v in self.histories.items():
            extra = ["t"]
            for i, n in enumerate(v.shape[len(self.shape) + 1 :]):
                dims[f"{k}_dim{i}"] = n
                extra.append(f"{k}_dim{i}")
            variables.append((f"history_{k}", (*member_dims, *extra), v, {"units": self.units.get(k, "?")}))
        flags = {  # CF flags: what each status code means
            "flag_values": np.array([c.value for c in ScanStatus], dtype=np.int32),
            "flag_meanings": " ".join(c.name.lower() for c in ScanStatus),
        }
        variables.append(("status", tuple(member_dims), self.status, flags))
        variables.append(("num_accepted_steps", tuple(member_dims), self.num_accepted_steps, {"units": "1"}))
        return dims, coords, variables

    def to_xarray(self):
        """An `xarray.Dataset` (only if xarray is installed; it is not a dependency of jaxhoist)."""
        try:
            import xarray as xr  # pyright: ignore[reportMissingImports]  # xarray is optional
        except ImportError:
            raise ImportError(
                "to_xarray() needs xarray, which jaxhoist does not depend on: "
                "`pip install xarray`, use to_netcdf() and open the file with any netCDF reader, or use "
                "ScanResult.data / .coords directly"
            ) from None
        _, coords, variables = self._layout()
        return xr.Dataset(
            {k: (d, v, a) for k, d, v, a in variables},
            coords={k: (d, v, a) for k, d, v, a in coords},
            attrs={"format": FORMAT},
        )

    def to_netcdf(self, path: str | Path) -> Path:
        """Write the dataset as a classic netCDF file (64-bit offsets), readable by xarray, NCO, ncview,
        MATLAB and the like: one dimension per grid parameter (or `member`), `t` for histories, one
        component dimension per vector observable (labels in a text coordinate), units and descriptions as
        attributes, failure reasons and the scan's metadata as JSON text in global attributes. Names that
        netCDF does not allow (brackets) become '_' (`"load.mass_centre[0]"` -> `load.mass_centre_0_`); the
        original path is kept in the `path` attribute."""
        from ..._io.netcdf import nc_name, nc_variable, write_netcdf

        dims, coords, variables = self._layout()
        nc_dims = {nc_name(d): n for d, n in dims.items()}
        # CF: the parameters along `member` are auxiliary coordinates of every variable on that dimension
        aux = " ".join(nc_name(p) for p in self.params) if self.mode != "grid" else ""
        out = [
            nc_variable(k, d, v, a, nc_dims, aux if "member" in d and k not in self.params else "")
            for k, d, v, a in [*coords, *variables]
        ]
        attrs = {
            "title": f"jaxhoist scan of {self.attrs.get('scenario', '?')}",
            "format": FORMAT,
            "scan_mode": self.mode,
            "params": ", ".join(self.params),
            "reasons_json": json.dumps({str(k): v for k, v in self.reasons.items()}),
            "attrs_json": json.dumps(self.attrs, default=json_default),
        }
        return write_netcdf(path, nc_dims, out, attrs)
