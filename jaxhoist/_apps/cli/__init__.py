"""The `jaxhoist` command line: the parser, `main` and the command's `entry_point` (`app`), one module per
command (`simulate`, `animate`, `scan`, `bifurcation`, `identify`), what they share (`common`) and the
progress bars that draw the library's callbacks (`progress`). It imports the library; nothing in the library
imports it."""

from .app import entry_point as entry_point
from .app import main as main
