"""companion: LQR side-by-side companion control for differential-drive robots."""

from companion import _jit

__version__ = "0.1.0"

_jit.install()
