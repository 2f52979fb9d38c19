"""onnxruntime execution providers of a detector: accelerators where a node has one.

:class:`Providers` is the typed setting (``ObjectDetector(providers=...)``): the execution providers in
onnxruntime's own names, in order of preference (``"CUDAExecutionProvider"``, ``"TensorrtExecutionProvider"``,
``"OpenVINOExecutionProvider"``, ..., ``"CPUExecutionProvider"``: the names ``onnxruntime.get_all_providers()``
lists, https://onnxruntime.ai/docs/execution-providers/), ``required`` (a provider missing on the node fails the
analytics instead of falling back to the CPU), ``num_gpus`` (Ray's logical GPUs the analytics' actor asks for;
default 1 when a GPU provider is named, :data:`GPU_PROVIDERS`) and per-provider ``options`` (onnxruntime's
provider options, e.g. ``{"OpenVINOExecutionProvider": {"device_type": "GPU"}}``).

:func:`open_session` opens the onnxruntime session with them on the node that runs the analytics: the providers
this onnxruntime build does not offer (``onnxruntime.get_available_providers()``) and those it could not load
(absent from the session's ``get_providers()``, e.g. CUDA libraries missing) are dropped with a clear message
(:class:`SessionProviders`, logged, recorded by the detector), the CPU provider always last; when ``required``,
:class:`ProviderUnavailableError` instead. A plain ``onnxruntime`` wheel offers only the CPU (and Azure) providers:
the GPU and OpenVINO builds are other wheels (``onnxruntime-gpu``, ``onnxruntime-openvino``) that replace it.
"""
from __future__ import annotations

import difflib
import logging
import math
import socket
from dataclasses import dataclass
from typing import Any

from pydantic import BaseModel, ConfigDict, StrictBool, ValidationError, field_validator, \
    model_validator

__all__ = ["CPU_PROVIDER", "GPU_PROVIDERS", "Providers", "ProviderUnavailableError", "SessionProviders",
           "providers_setting", "validation_message", "known_providers", "missing_here", "open_session"]

log = logging.getLogger(__name__)

CPU_PROVIDER = "CPUExecutionProvider"

#: providers that run on a GPU, for which the analytics' actor asks Ray for ``num_gpus`` (default 1) so that Ray
#: places it on a node that has one (onnxruntime's names; ROCm's provider left onnxruntime in 1.23 but older
#: builds have it). OpenVINO is not in it: it runs on Intel CPUs as well (its ``device_type`` option picks)
GPU_PROVIDERS = frozenset({"CUDAExecutionProvider", "TensorrtExecutionProvider", "NvTensorRTRTXExecutionProvider",
                           "MIGraphXExecutionProvider", "ROCMExecutionProvider", "DmlExecutionProvider"})


class ProviderUnavailableError(RuntimeError):
    """A provider the user required (``Providers(required=True)``) is not available on the node that opens the
    session; the message names it, the node and what this onnxruntime offers."""


def known_providers() -> list[str]:
    """Every provider name this onnxruntime knows (``onnxruntime.get_all_providers()``, built or not), plus
    :data:`GPU_PROVIDERS` (names of other builds that a newer or older wheel may lack)."""
    import onnxruntime as ort  # lazy: heavy onnxruntime

    return list(dict.fromkeys([*ort.get_all_providers(), *sorted(GPU_PROVIDERS)]))


def _hint(name: str, known: list[str]) -> str:
    low = {k.lower(): k for k in known}
    for cand in (name.lower(), name.lower() + "executionprovider"):
        if cand in low:
            return f" (did you mean {low[cand]!r}?)"
    close = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


class Providers(BaseModel):
    """Where a detector's onnxruntime session runs (see the module docstring). Fields: ``names`` (at least one, no
    duplicates, each an onnxruntime provider name), ``required`` (bool), ``num_gpus`` (Ray logical GPUs, a finite
    number >= 0; None: 1 with a GPU provider, else 0; fractions share a GPU between actors), ``options``
    (provider name -> its options, each a named provider). Raises ValueError naming the field and the value
    (``providers.names: 'cuda' (item 0) is not an onnxruntime execution provider (did you mean
    'CUDAExecutionProvider'?) ...``)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    names: tuple[str, ...]
    required: StrictBool = False
    num_gpus: float | None = None
    options: dict[str, dict[str, str]] = {}

    def __init__(self, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as e:  # one line naming the field and the value, raised from here (input, exit 2)
            raise ValueError(validation_message(e, "providers")) from None

    @field_validator("names")
    @classmethod
    def _names(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        if not v:
            raise ValueError("names no provider; give at least one, e.g. ['CUDAExecutionProvider', "
                             "'CPUExecutionProvider']")
        dup = sorted({n for n in v if v.count(n) > 1})
        if dup:
            raise ValueError(f"names {dup} more than once")
        known = known_providers()
        for i, n in enumerate(v):
            if n not in known:
                raise ValueError(f"{n!r} (item {i}) is not an onnxruntime execution provider{_hint(n, known)}; "
                                 f"onnxruntime names them {known}")
        return v

    @field_validator("num_gpus", mode="before")
    @classmethod
    def _gpus(cls, v: Any) -> float | None:
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
                              or v < 0):
            raise ValueError(f"must be a number of Ray GPUs >= 0 (fractions share a GPU), got {v!r}")
        return v

    @model_validator(mode="after")
    def _options(self) -> "Providers":
        bad = [k for k in self.options if k not in self.names]
        if bad:
            raise ValueError(f"options names provider(s) {bad} that are not in names {list(self.names)}")
        return self

    @property
    def gpu(self) -> bool:
        """True when a provider of :data:`GPU_PROVIDERS` is named."""
        return any(n in GPU_PROVIDERS for n in self.names)

    def ray_gpus(self) -> float:
        """The GPUs (Ray's ``num_gpus``) the analytics' actor asks for: ``num_gpus``, else 1 with a GPU provider,
        else 0."""
        if self.num_gpus is not None:
            return float(self.num_gpus)
        return 1.0 if self.gpu else 0.0


def providers_setting(value: Any, name: str = "detector") -> Providers | None:
    """``value`` as a :class:`Providers`: None (the CPU, as before), a :class:`Providers`, a provider name or a list
    of them (``required`` False). Raises ValueError starting with ``analytics {name!r}: providers`` and naming the
    field and the value."""
    if value is None or isinstance(value, Providers):
        return value
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, (list, tuple)):
        raise ValueError(f"analytics {name!r}: providers must be a provider name, a list of them or a "
                         f"Providers(...), got {value!r}")
    try:
        return Providers(names=tuple(value))
    except ValueError as e:
        raise ValueError(f"analytics {name!r}: {e}") from None


def validation_message(e: ValidationError, pre: str) -> str:
    """One clause per error of ``e``: ``{pre}.{field}: {message}`` (pydantic's own type errors with the value
    given; ours name it already)."""
    parts = []
    for err in e.errors():
        loc = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in err["loc"])
        msg = str(err["msg"]).removeprefix("Value error, ")
        if err["type"] != "value_error":
            msg += f", got {err.get('input')!r}"
        parts.append(f"{pre}{loc}: {msg}")
    return "; ".join(parts)


def missing_here(providers: Providers) -> list[str]:
    """The providers of ``providers`` this process's onnxruntime build does not offer
    (``onnxruntime.get_available_providers()``)."""
    import onnxruntime as ort  # lazy: heavy onnxruntime

    avail = set(ort.get_available_providers())
    return [n for n in providers.names if n not in avail]


@dataclass(frozen=True)
class SessionProviders:
    """What a session runs on: ``requested`` (the user's names, None: the default CPU), ``used`` (the session's
    ``get_providers()``, in order), ``fallback`` (the message when a requested provider is not used, else None) and
    ``host`` (the node's host name)."""

    requested: tuple[str, ...] | None
    used: tuple[str, ...]
    fallback: str | None
    host: str

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: ``providers_requested``, ``providers``, ``provider_fallback``, ``host``."""
        return {"providers_requested": list(self.requested or ()), "providers": list(self.used),
                "provider_fallback": self.fallback, "host": self.host}


_INSTALL = ("a plain `onnxruntime` wheel has the CPU provider only: install `onnxruntime-gpu` (CUDA, TensorRT) "
            "or `onnxruntime-openvino` (OpenVINO) in its place on that node (docs/perception.md, \"Accelerators\")")


def open_session(path: str, sess_options: Any, providers: Providers | None, what: str = "the model"):
    """The onnxruntime ``InferenceSession`` of model ``path`` on ``providers`` (None: the CPU provider alone) and a
    :class:`SessionProviders` saying what it runs on. Providers this build does not offer or could not load are
    dropped with a warning (logged; the message is ``SessionProviders.fallback``) and the CPU provider is always
    last. ``what`` names the session in the messages. Raises :class:`ProviderUnavailableError` when
    ``providers.required`` and a named provider is not used, else what onnxruntime raises for the model."""
    import onnxruntime as ort  # lazy: heavy onnxruntime

    host = socket.gethostname()
    if providers is None:
        sess = ort.InferenceSession(path, sess_options=sess_options, providers=[CPU_PROVIDER])
        return sess, SessionProviders(None, tuple(sess.get_providers()), None, host)
    avail = ort.get_available_providers()
    offered = [n for n in providers.names if n in avail]
    missing = [n for n in providers.names if n not in avail]
    where = f"{what} on node {host!r} (onnxruntime {ort.__version__} offers {avail})"
    if missing and providers.required:
        raise ProviderUnavailableError(f"{where}: required provider(s) {missing} not in this build; {_INSTALL}")
    use = offered if CPU_PROVIDER in offered else [*offered, CPU_PROVIDER]
    opts = [dict(providers.options.get(n, {})) for n in use]
    sess = ort.InferenceSession(path, sess_options=sess_options, providers=use, provider_options=opts)
    used = tuple(sess.get_providers())
    unloaded = [n for n in offered if n not in used]  # in the build, but it could not start (libraries, device)
    if unloaded and providers.required:
        raise ProviderUnavailableError(f"{where}: required provider(s) {unloaded} could not be loaded (see "
                                       f"onnxruntime's log above: CUDA/cuDNN libraries, a device)")
    note = None
    if missing or unloaded:
        why = ([f"{missing} not in this build ({_INSTALL})"] if missing else []) + \
            ([f"{unloaded} could not be loaded"] if unloaded else [])
        note = f"{where}: provider(s) " + "; ".join(why) + f"; running on {list(used)}"
        log.warning("%s", note)
    return sess, SessionProviders(tuple(providers.names), used, note, host)
