"""Parameter scans: `scan` (`run`: members -> layout -> chunk loop -> `ScanResult`), the members as objects
(`sweep`: `Sweep`, `Grid`, `Points`), its own accuracy (`accuracy`: `AccuracyCheck`), the layout (`layout`:
`BatchOptions`), the result (`result`: `ScanResult`) and what a scan reports per chunk (`progress`:
`Progress`). Imports the numerics, `_io` and nothing else of `_apps`."""

from .accuracy import AccuracyCheck as AccuracyCheck
from .layout import BatchOptions as BatchOptions
from .progress import Progress as Progress
from .result import ScanResult as ScanResult
from .run import scan as scan
from .sweep import Grid as Grid
from .sweep import Points as Points
from .sweep import Sweep as Sweep
