"""Class names carried in an ONNX detector's metadata (``custom_metadata_map``), as Ultralytics writes them and as
``aerodaas train detector`` writes them: ``names`` is the ``str`` of ``{index: name}`` (or of a list)."""
from __future__ import annotations

import ast

__all__ = ["metadata_names", "metadata_imgsz"]


def metadata_names(meta: dict[str, str]) -> list[str] | None:
    """Class names from an ONNX model's metadata ``names`` as Ultralytics writes it (``str`` of a dict
    ``{index: name}`` or of a list), in index order; None when absent. Raises ValueError for a ``names`` entry
    that is not a dict/list literal or whose indices are not ``0..n-1``."""
    raw = meta.get("names")
    if raw is None:
        return None
    try:
        names = ast.literal_eval(raw)
    except (ValueError, SyntaxError):
        raise ValueError(f"model metadata names={raw[:80]!r} is not a dict or list literal") from None
    if isinstance(names, (list, tuple)):
        return [str(n) for n in names]
    if isinstance(names, dict):
        d = {int(k): str(v) for k, v in names.items()}
        if sorted(d) != list(range(len(d))):
            raise ValueError(f"model metadata names has indices {sorted(d)[:10]}..., expected 0..{len(d) - 1}")
        return [d[i] for i in range(len(d))]
    raise ValueError(f"model metadata names={raw[:80]!r} is not a dict or list literal")


def metadata_imgsz(meta: dict[str, str]) -> tuple[int, int] | None:
    """A dynamic-size model's default input ``(H, W)`` pixels from its metadata ``imgsz`` (``"[H, W]"`` or ``"N"``),
    or None when absent or not two positive integers."""
    raw = meta.get("imgsz")
    if not raw:
        return None
    try:
        v = ast.literal_eval(raw)
        h, w = (v, v) if isinstance(v, int) else (int(v[0]), int(v[1]))
    except (ValueError, SyntaxError, TypeError, IndexError):
        return None
    return (int(h), int(w)) if h > 0 and w > 0 else None
