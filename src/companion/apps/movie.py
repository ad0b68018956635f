"""Animation files: the name checked before a run (.gif, or .mp4 where ffmpeg is on PATH),
and the frames a figure's canvas draws written to it atomically (Pillow for GIF, ffmpeg for
MP4, both through :mod:`matplotlib.animation`'s writers)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path

from matplotlib import animation
from matplotlib.figure import Figure
from PIL import Image

from companion.apps.args import UsageError, output_file
from companion.apps.progress import counted
from companion.io import atomic_write

EXTENSIONS = (".gif", ".mp4")


def target_arg(text: str, flag: str = "--animate") -> Path:
    """The animation file named by ``flag``, checked before any work: a .gif, or a .mp4 when
    ffmpeg is on PATH, in a folder that exists (or can be made) and can be written."""
    path = Path(text)
    suffix = path.suffix.lower()
    if suffix not in EXTENSIONS:
        raise UsageError(f"{flag} {text}: expected a file name ending in .gif or .mp4, got "
                         f"{path.suffix or 'no extension'!r}")
    if suffix == ".mp4" and not animation.FFMpegWriter.isAvailable():
        raise UsageError(f"{flag} {text}: .mp4 needs ffmpeg on PATH, which is not there; "
                         f"write a .gif instead")
    return output_file(text, flag)


def even_inches(width: float, dpi: float) -> float:
    """``width`` (in) rounded up to an even number of pixels (h264 needs them)."""
    return 2 * math.ceil(width * dpi / 2) / dpi


def _palette(frame: Image.Image) -> Image.Image:
    """A palette for every frame: the first frame's commonest colours exactly (white, the
    grid, the fills and lines: no tinted background), then a median cut of it for the
    anti-aliased blends, leaving out colours within 8 levels of one kept (Pillow's palette
    lookup would mistake them for each other)."""
    common = [rgb for _, rgb in sorted(frame.getcolors(frame.width * frame.height),
                                       reverse=True)[:96]]
    cut = frame.quantize(colors=160, method=Image.Quantize.MEDIANCUT).getpalette()
    kept: list[tuple[int, ...]] = []
    for rgb in [*common, *zip(cut[0::3], cut[1::3], cut[2::3])]:
        if len(kept) < 256 and all(max(abs(a - b) for a, b in zip(rgb, k)) > 8 for k in kept):
            kept.append(tuple(rgb))
    palette = Image.new("P", (1, 1))
    palette.putpalette([c for rgb in kept for c in rgb])
    return palette


class _GifWriter(animation.PillowWriter):
    """Pillow's GIF writer taking each frame as the canvas already drew it, held as an 8-bit
    palette image on one shared palette (a quarter of the memory, and Pillow then stores only
    the pixels that change), and naming the format (the file has a temporary name)."""

    def setup(self, fig, outfile, dpi=None):
        super().setup(fig, outfile, dpi=dpi)
        self._palette: Image.Image | None = None

    def grab_frame(self, **savefig_kwargs):
        canvas = self.fig.canvas
        frame = Image.frombuffer("RGBA", canvas.get_width_height(), canvas.buffer_rgba(),
                                 "raw", "RGBA", 0, 1).convert("RGB")
        if self._palette is None:
            self._palette = _palette(frame)
        self._frames.append(frame.quantize(palette=self._palette, dither=Image.Dither.NONE))

    def finish(self):
        self._frames[0].save(self.outfile, format="GIF", save_all=True,
                             append_images=self._frames[1:], duration=round(1000 / self.fps),
                             loop=0)


class _Mp4Writer(animation.FFMpegWriter):
    """ffmpeg's writer taking each frame as the canvas already drew it, in MP4 whatever the
    file's (temporary) name."""

    def __init__(self, fps: int):
        super().__init__(fps=fps, extra_args=["-f", "mp4"])

    def grab_frame(self, **savefig_kwargs):
        self._proc.stdin.write(self.fig.canvas.buffer_rgba())


def write(path: Path, fig: Figure, render: Callable[[int], None], rows: Sequence[int],
          fps: int) -> None:
    """Write ``path`` (.gif or .mp4) atomically: for each of ``rows``, ``render(row)`` draws
    the frame on ``fig``'s canvas, and the frame is taken from there (a bar of the frames on
    stderr when it takes long)."""
    writer = _Mp4Writer(fps) if path.suffix.lower() == ".mp4" else _GifWriter(fps=fps)

    def frames(tmp: Path) -> None:
        with writer.saving(fig, str(tmp), dpi=fig.dpi):
            for k in counted(rows, len(rows), "frame", f"drawing {path.name}"):
                render(int(k))
                writer.grab_frame()

    atomic_write(path, frames)
