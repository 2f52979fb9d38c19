"""The problems of a labelled set, collected while it is read and reported at once (:class:`LabelError`)."""
from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["LabelError", "Checker", "EDGE_TOLERANCE_PX"]

#: a box may reach this far (pixels) outside its image before it is an error (labelling tools round outwards)
EDGE_TOLERANCE_PX = 2.0
_MAX_REPORTED = 20


class LabelError(ValueError):
    """The labelled set cannot be trained on; ``problems`` lists every problem found (file:line: what)."""

    def __init__(self, where: str, problems: list[str]) -> None:
        self.problems = problems
        shown = "\n  ".join(problems[:_MAX_REPORTED])
        more = f"\n  ... and {len(problems) - _MAX_REPORTED} more" if len(problems) > _MAX_REPORTED else ""
        super().__init__(f"{where}: {len(problems)} problem(s) in the labels:\n  {shown}{more}")


@dataclass
class Checker:
    """Collects ``problems`` (``"file:line: what"``) while a set is read."""

    problems: list[str] = field(default_factory=list)

    def box(self, where: str, x0: float, y0: float, x1: float, y1: float, hw: tuple[int, int]) -> bool:
        """True when the box (pixels) has a positive size and lies in the ``(height, width)`` image, within
        :data:`EDGE_TOLERANCE_PX`; else a problem naming ``where`` and the box is noted and False returned."""
        h, w = hw
        if not (x1 > x0 and y1 > y0):
            self.problems.append(f"{where}: box ({x0:.1f}, {y0:.1f}, {x1:.1f}, {y1:.1f}) has a non-positive size")
            return False
        t = EDGE_TOLERANCE_PX
        if x0 < -t or y0 < -t or x1 > w + t or y1 > h + t:
            self.problems.append(f"{where}: box ({x0:.1f}, {y0:.1f}, {x1:.1f}, {y1:.1f}) px lies outside the "
                                 f"{w}x{h} image")
            return False
        return True
