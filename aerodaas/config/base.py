"""The configuration's foundations: :class:`ConfigError`, the strict base of every section (unknown keys refused,
finite numbers, strict types), the "did you mean" helper and where the files an environment names are found. The
documented physical bounds the sections check are in :mod:`aerodaas.model.bounds`."""
from __future__ import annotations

import difflib
from pathlib import Path


from pydantic import BaseModel, ConfigDict


DATA_DIR_ENV = "AERODAAS_DATA_DIR"
#: the prefix of a file name in an environment file that names one of the images shipped in the package
#: (:data:`PACKAGE_IMAGERY_DIR`): ``"image": "package:brighton_beach_DJI_0025_8cm.jpg"``
PACKAGE_PREFIX = "package:"
#: the package's imagery folder (its README.md says where each image comes from)
PACKAGE_IMAGERY_DIR = Path(__file__).resolve().parents[1] / "sim" / "ground"


def packaged_file(name: str, field: str) -> Path:
    """The packaged image that ``package:NAME`` names: ``NAME``, a plain file name, in :data:`PACKAGE_IMAGERY_DIR`.

    Raises ConfigError naming ``field``, the name and the packaged images when ``NAME`` is not one of them (a
    folder or ``..`` in it is refused, so it never reaches outside that folder)."""
    rest = name[len(PACKAGE_PREFIX):]
    path = PACKAGE_IMAGERY_DIR / rest
    if rest and Path(rest).name == rest and rest not in (".", "..") and path.is_file():
        return path
    shipped = sorted(p.name for p in PACKAGE_IMAGERY_DIR.glob("*") if p.suffix.lower() in (".jpg", ".png"))
    raise ConfigError(f"{field}: {name!r} is not a packaged image (the package ships: "
                      f"{', '.join(PACKAGE_PREFIX + s for s in shipped) or 'none'})")


class ConfigError(ValueError):
    """A malformed environment file; the message names each bad field and its value."""


class _Cfg(BaseModel):
    """Every configuration section: unknown keys are refused (with a "did you mean" suggestion, see
    :func:`_format_errors`), numbers must be finite (no NaN/Infinity), and types are strict: ``"yes"`` or ``1``
    is not a boolean, ``"3"`` is not a number (JSON has real booleans and numbers)."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


def did_you_mean(word: str, choices) -> str:
    """``" (did you mean 'width'?)"`` for the closest of ``choices`` to a misspelt ``word`` (difflib), else ``""``."""
    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def plugin_config_error(what: str, cls: type, err: BaseException) -> str:
    """The message for an exception other than pydantic's ValidationError raised while a plug-in's ``Config``
    validated its settings (a validator raising TypeError or KeyError, which pydantic passes on as it is): worded
    as that plug-in's configuration error, naming ``what`` (``sensor type 'gas'``), the class and the exception,
    never a traceback."""
    config = getattr(cls, "Config", None)
    model = f"{config.__module__}.{config.__qualname__}" if isinstance(config, type) else repr(config)
    return (f"{what}: the settings were refused by the plug-in's Config ({model}): {type(err).__name__}: "
            f"{str(err)[:300] or '(no message)'}")
