"""Model files of the detectors: where each comes from (:data:`MODELS`, pinned URL and sha256), how one is found
(:func:`resolve_model`: an explicit path, ``$AERODAAS_MODEL_DIR``, the user cache, then a verified download) and
how the driver ships a resolved file to the node that runs the analytics (:class:`ShippedModel`). The shared data
manifest (``MANIFEST.md`` next to the models) documents the same contract."""
from __future__ import annotations

import functools
import hashlib
import logging
import os
import pathlib
import tempfile
import urllib.error
import urllib.request
from dataclasses import dataclass

__all__ = ["MODEL_DIR_ENV", "ModelSpec", "MODELS", "ModelNotFoundError", "ModelChecksumError", "resolve_model",
           "model_cache_dir", "ShippedModel"]

log = logging.getLogger(__name__)

MODEL_DIR_ENV = "AERODAAS_MODEL_DIR"


# ----------------------------------------------------------------------------------------------------------------
# Model registry and resolution
# ----------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ModelSpec:
    """Where a model file comes from.

    ``file``: file name looked up in the model folders; ``url``: download URL pinned to a commit (empty for a
    model shipped inside the package); ``sha256``: hex digest of the exact bytes; ``license``: SPDX id; ``source``:
    human-readable provenance; ``packaged``: the file is in :data:`PACKAGED_MODELS_DIR` (installed with AeroDaaS).
    """

    file: str
    url: str
    sha256: str
    license: str
    source: str = ""
    packaged: bool = False


#: the models installed with the package (the aerial detector and its model card)
PACKAGED_MODELS_DIR = pathlib.Path(__file__).resolve().parent / "models"


MODELS: dict[str, ModelSpec] = {
    "aerial_nano": ModelSpec(
        file="aerial_nano.onnx",
        url="",
        sha256="69fa98c02be3df5b3598d6c2b07f568b814af99ce599b5961e3bd1edf9c90eed",
        license="CC-BY-SA-4.0",
        source="YOLOX-Nano (Apache-2.0) fine-tuned by `aerodaas train detector` on HIT-UAV (CC-BY-4.0) and "
        "jekhor/aerial-cars-dataset (CC-BY-3.0, CC-BY-SA-4.0); aerodaas/perception/models/MODEL_CARD.md",
        packaged=True,
    ),
    "yolox_nano": ModelSpec(
        file="yolox_nano.onnx",
        url="https://raw.githubusercontent.com/Kazuhito00/YOLOX-ONNX-TFLite-Sample/"
        "3d4f1119d0694200671c08069ecb847aa0d8495a/model/yolox_nano.onnx",
        sha256="695e750a5d5754bb5a8d5325643b59282191a7e7a564e435a415fd3c578eab14",
        license="Apache-2.0",
        source="Kazuhito00/YOLOX-ONNX-TFLite-Sample model/yolox_nano.onnx @ 3d4f1119 (upstream Megvii YOLOX)",
    ),
    "nanodet_plus_m_416": ModelSpec(
        file="nanodet_plus_m_416.onnx",
        url="https://raw.githubusercontent.com/hpc203/nanodet-opncv-dnn-cpp-python/"
        "15dd99c651d53c824f51d1eb5faddbd4f3d69bbc/nanodet_m.onnx",
        sha256="4b82da9944b88577175ee23a459dce2e26e6e4be573def65b1055dc2d9720186",
        license="Apache-2.0",
        source="hpc203/nanodet-opncv-dnn-cpp-python nanodet_m.onnx @ 15dd99c6; same bytes as opencv/opencv_zoo "
        "models/object_detection_nanodet/object_detection_nanodet_2022nov.onnx (RangiLyu NanoDet-Plus)",
    ),
}


#: Short names accepted by :func:`resolve_model` and :func:`make_detector`.
_ALIASES = {"yolox": "yolox_nano", "nanodet": "nanodet_plus_m_416", "aerial": "aerial_nano"}


class ModelNotFoundError(FileNotFoundError):
    """No usable model file: not at the given path, not in the model folders, and the download failed."""


class ModelChecksumError(ValueError):
    """A model file's sha256 differs from the registry (wrong, truncated or corrupted file)."""


def _sha256_file(path: pathlib.Path) -> str:
    """sha256 hex digest of ``path``; cached per (resolved path, mtime_ns, size) so repeated resolutions are cheap
    and a rewritten file is hashed again. Raises OSError when ``path`` cannot be read."""
    st = path.stat()
    return _sha256_of(str(path.resolve()), st.st_mtime_ns, st.st_size)


@functools.cache
def _sha256_of(path: str, mtime_ns: int, size: int) -> str:
    """sha256 hex digest of the file ``path`` as of (``mtime_ns``, ``size``): a memo of a pure function of its key
    (``functools.cache``, thread-safe; two threads may hash the same file once each), instead of a hand-kept dict."""
    del mtime_ns, size  # part of the cache key only
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _verify(path: pathlib.Path, spec: ModelSpec) -> None:
    digest = _sha256_file(path)
    if digest != spec.sha256:
        raise ModelChecksumError(
            f"model file {path} has sha256 {digest}, expected {spec.sha256} for {spec.file} "
            f"({spec.source}); the file is wrong or corrupted: replace or delete it"
        )


def model_cache_dir() -> pathlib.Path:
    """The user cache folder for downloaded models: ``$XDG_CACHE_HOME/aerodaas/models``, else
    ``~/.cache/aerodaas/models``. Not created here."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return pathlib.Path(base) / "aerodaas" / "models"


def _download(spec: ModelSpec, dest_dir: pathlib.Path, timeout: float = 60.0) -> pathlib.Path:
    """Download ``spec.url`` into ``dest_dir`` via a temp file, verify sha256, then move it in place atomically."""
    dest_dir.mkdir(parents=True, exist_ok=True)
    dest = dest_dir / spec.file
    fd, tmp_name = tempfile.mkstemp(prefix=spec.file + ".", suffix=".part", dir=dest_dir)
    tmp = pathlib.Path(tmp_name)
    try:
        h = hashlib.sha256()
        with os.fdopen(fd, "wb") as out, urllib.request.urlopen(spec.url, timeout=timeout) as resp:
            for chunk in iter(lambda: resp.read(1 << 16), b""):
                h.update(chunk)
                out.write(chunk)
        digest = h.hexdigest()
        if digest != spec.sha256:
            raise ModelChecksumError(
                f"downloaded {spec.url} has sha256 {digest}, expected {spec.sha256}; not installed as {dest}"
            )
        os.replace(tmp, dest)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    log.info("downloaded %s to %s", spec.url, dest)
    return dest


def _packaged_file(name: str, spec: ModelSpec) -> pathlib.Path:
    """The file of a model installed with the package, sha256-verified. Raises ModelNotFoundError when it is
    missing (a broken install), ModelChecksumError when its bytes differ."""
    cand = PACKAGED_MODELS_DIR / spec.file
    if not cand.is_file():
        raise ModelNotFoundError(f"model {name!r}: {cand} is missing from the installed package; reinstall aerodaas")
    _verify(cand, spec)
    return cand


def resolve_model(name: str = "yolox_nano", path: str | os.PathLike | None = None, *,
                  allow_download: bool = True) -> pathlib.Path:
    """Locate the ONNX file of model ``name`` (a key of :data:`MODELS`, or ``"yolox"``/``"nanodet"``); return its path.

    Search order (a model shipped inside the package, ``ModelSpec.packaged``, is only looked up there, and
    verified):

    1. ``path`` if given: used as is (a user may bring their own ONNX file, so its sha256 is **not** checked);
       raises :class:`ModelNotFoundError` naming the path if it is not a file.
    2. ``$AERODAAS_MODEL_DIR/<file>``.
    3. The user cache, ``$XDG_CACHE_HOME/aerodaas/models/<file>`` or ``~/.cache/aerodaas/models/<file>``.
    4. If ``allow_download``: download from the commit-pinned URL in :data:`MODELS` with ``urllib`` into the
       cache folder (temp file, sha256 verified, then moved in place).

    Files found in 2 and 3 are verified against the registry sha256 (cached per path and mtime). A mismatch in
    ``$AERODAAS_MODEL_DIR`` raises :class:`ModelChecksumError` naming the file; a mismatching cached file is
    replaced by a fresh download when possible, otherwise the error is raised.

    Raises ``ValueError`` for an unknown ``name``, :class:`ModelChecksumError` as above, and
    :class:`ModelNotFoundError` (a ``FileNotFoundError``) when nothing is found and the download is disabled or
    fails (offline); its message says to set ``AERODAAS_MODEL_DIR`` and includes the download error.
    """
    name = _ALIASES.get(name, name)
    if name not in MODELS:
        raise ValueError(f"unknown model {name!r}; known models: {', '.join(sorted(MODELS))}")
    spec = MODELS[name]

    if path is not None:
        p = pathlib.Path(path).expanduser()
        if not p.is_file():
            raise ModelNotFoundError(f"model file {str(p)!r} for {name!r} does not exist (or is not a file)")
        return p

    searched: list[str] = []
    if spec.packaged:  # installed with the package: always there, always verified
        return _packaged_file(name, spec)
    env_dir = os.environ.get(MODEL_DIR_ENV)
    if env_dir:
        cand = pathlib.Path(env_dir).expanduser() / spec.file
        searched.append(str(cand))
        if cand.is_file():
            _verify(cand, spec)
            return cand
    else:
        searched.append(f"${MODEL_DIR_ENV} (not set)")

    cache = model_cache_dir()
    cand = cache / spec.file
    searched.append(str(cand))
    cache_error: ModelChecksumError | None = None
    if cand.is_file():
        try:
            _verify(cand, spec)
            return cand
        except ModelChecksumError as e:  # corrupt cache entry: try to replace it by a verified download
            if not allow_download:
                raise
            cache_error = e
            log.warning("%s; downloading a fresh copy", e)

    if allow_download:
        try:
            return _download(spec, cache)
        except ModelChecksumError:
            raise
        except (urllib.error.URLError, OSError, TimeoutError, ValueError) as e:
            if cache_error is not None:
                raise cache_error from e
            reason = f"download from {spec.url} failed: {type(e).__name__}: {e}"
            cause: BaseException | None = e
    else:
        reason = "download disabled (allow_download=False)"
        cause = None
    raise ModelNotFoundError(
        f"model {name!r} ({spec.file}) not found; searched: {', '.join(searched)}; {reason}. "
        f"Set {MODEL_DIR_ENV} to a folder containing {spec.file} (sha256 {spec.sha256}, from {spec.source}), "
        f"or pass an explicit model path."
    ) from cause


@dataclass(frozen=True)
class ShippedModel:
    """A model file's bytes, resolved once where the driver runs and shipped with an actor (pickled into its
    arguments, so through Ray's object store) to the nodes that run the detector: cloud nodes need no model folder,
    no cache and no internet. ``file``: the file name; ``sha256``: hex digest of ``data``.

    :meth:`path_on_this_node` returns ``path`` if that file exists here with the same sha256 (the driver's node, or
    a cluster sharing the folder), else the bytes written once to
    ``<model cache>/shipped/<sha256[:16]>-<file>`` (temp file, then an atomic rename, so concurrent actors on one
    node never see a half-written file)."""

    file: str
    sha256: str
    data: bytes

    @classmethod
    def read(cls, path: str | os.PathLike) -> "ShippedModel":
        """The bytes of the model file at ``path``. Raises ModelNotFoundError if it is not a readable file."""
        p = pathlib.Path(path)
        try:
            data = p.read_bytes()
        except OSError as e:
            raise ModelNotFoundError(f"model file {str(p)!r} cannot be read to ship it to the cluster: {e}") from e
        return cls(file=p.name, sha256=hashlib.sha256(data).hexdigest(), data=data)

    def __repr__(self) -> str:  # never the bytes
        return f"ShippedModel(file={self.file!r}, sha256={self.sha256[:16]}..., {len(self.data)} bytes)"

    def path_on_this_node(self, path: str | os.PathLike | None = None) -> pathlib.Path:
        """A local file holding exactly these bytes (see the class docstring). Raises OSError if the cache folder
        cannot be written."""
        if path is not None:
            p = pathlib.Path(path)
            if p.is_file() and _sha256_file(p) == self.sha256:
                return p
        dest_dir = model_cache_dir() / "shipped"
        dest = dest_dir / f"{self.sha256[:16]}-{self.file}"
        if dest.is_file() and _sha256_file(dest) == self.sha256:
            return dest
        dest_dir.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=dest.name + ".", suffix=".part", dir=dest_dir)
        try:
            with os.fdopen(fd, "wb") as out:
                out.write(self.data)
            os.replace(tmp, dest)
        except BaseException:
            pathlib.Path(tmp).unlink(missing_ok=True)
            raise
        log.info("model %s written from the driver's copy to %s", self.file, dest)
        return dest
