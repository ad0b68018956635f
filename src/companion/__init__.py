"""companion: LQR side-by-side companion control for differential-drive robots."""

from companion import _jitcache

__version__ = "0.1.0"

_jitcache.install()
