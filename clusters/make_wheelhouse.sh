#!/usr/bin/env bash
# Fill a wheelhouse for cluster nodes without internet:   clusters/make_wheelhouse.sh [DIR]
#
# DIR defaults to wheelhouse/ in the repository root, which `ray up` syncs to every node with the checkout; the
# clusters' setup commands then install from it alone (pip --no-index --find-links). It holds binary wheels of the
# project's dependencies (pyproject.toml), with Ray pinned to the version you run `ray up` with (the driver, the
# autoscaler and the nodes must agree), and the build backend of the editable install (setuptools, wheel).
#
# The wheels must suit the NODES: run this with their Python (NODE_PYTHON, default python3: same minor version,
# same CPU architecture and a glibc no newer than theirs), or pass pip's cross-download options in PIP_TARGET, e.g.
#   PIP_TARGET="--python-version 3.11 --platform manylinux2014_x86_64 --platform manylinux_2_28_x86_64" \
#       clusters/make_wheelhouse.sh
# RAY_VERSION overrides the Ray version (default: `import ray` with python3 here). Needs PyPI (or your index).
# Re-running adds only what is missing. Exit 1 if a download fails.
set -euo pipefail
REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
DEST=${1:-$REPO/wheelhouse}
NODE_PYTHON=${NODE_PYTHON:-python3}
RAY_VERSION=${RAY_VERSION:-$(python3 -c 'import ray; print(ray.__version__)')}
mkdir -p "$DEST"
reqs=$(mktemp)
trap 'rm -f "$reqs"' EXIT
python3 - "$REPO/pyproject.toml" "$RAY_VERSION" > "$reqs" <<'PY'
import re, sys
try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib
deps = tomllib.load(open(sys.argv[1], "rb"))["project"]["dependencies"]
for d in deps:
    name = re.split(r"[\[<>=!~ ;]", d, maxsplit=1)[0]
    print(f"ray[default]=={sys.argv[2]}" if name == "ray" else d)
print("setuptools>=69")  # [build-system] of pyproject.toml: the editable install builds offline too
print("wheel")
PY
# shellcheck disable=SC2086
"$NODE_PYTHON" -m pip download -q --disable-pip-version-check --only-binary=:all: ${PIP_TARGET:-} -d "$DEST" -r "$reqs"
echo "$(ls "$DEST" | wc -l) files in $DEST (Ray $RAY_VERSION)"
