"""Parameter identification: `identify` and its companions `residual_function`, `synthetic_measurement`
(`fit`), the compiled Levenberg-Marquardt fit (`core`), `FitOptions` and the fit's solver settings
(`options`), the fitted parameters and their reparameterisation (`parameters`) and `IdentificationResult`
(`result`)."""

from .fit import identify as identify
from .fit import residual_function as residual_function
from .fit import synthetic_measurement as synthetic_measurement
from .options import FitOptions as FitOptions
from .result import IdentificationResult as IdentificationResult
