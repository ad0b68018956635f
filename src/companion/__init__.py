"""companion: LQR side-by-side companion control for differential-drive robots."""

__version__ = "0.1.0"
