#!/usr/bin/env bash
# Wheels for an offline GPU machine whose Python already has a CUDA JAX but
# not the rest of pizero-ray's dependencies (the lent device machines: Python
# 3.12, JAX with its CUDA plugin, optax, orbax, chex, no Ray, no mctx, no
# network). Run it here, where pip can reach PyPI:
#
#   scripts/fetch-device-wheels.sh [DIR]      # default DIR: .whl (git-ignored)
#
# then, on the GPU machine, with DIR carried beside the repo:
#
#   python3 scripts/device_check.py --python python3 --wheels DIR
#
# device_check.py installs only what that interpreter lacks or has older.
# Ray's wheel is pruned of what a training never loads (its Java jar, the
# dashboard's web client, the RLlib/Serve/Data/Train/Tune/LLM libraries): 79
# MB become 40 MB, so that the repo and its wheels travel in one 64 MiB copy.
set -euo pipefail

dir=${1:-.whl}
python_version=${DEVICE_PYTHON_VERSION:-3.12}
mkdir -p "$dir"
python3 -m pip download --quiet --no-deps --only-binary=:all: --python-version "$python_version" \
    --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 \
    --platform manylinux2014_x86_64 -d "$dir" \
    ray==2.60.0 mctx==0.0.71 chex==0.1.92 tensorboardX==2.6.4 jsonschema jsonschema-specifications referencing rpds-py

python3 - "$dir" <<'PY'
import pathlib, sys, zipfile

DROP = ("ray/jars/", "ray/dashboard/client/build/", "ray/rllib/", "ray/serve/", "ray/llm/", "ray/data/",
        "ray/train/", "ray/tune/")
for wheel in pathlib.Path(sys.argv[1]).glob("ray-*.whl"):
    pruned = wheel.with_suffix(".pruned")
    with zipfile.ZipFile(wheel) as source, zipfile.ZipFile(pruned, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as out:
        for info in source.infolist():
            if info.filename.startswith(DROP):
                continue
            data = source.read(info)
            if info.filename.endswith(".dist-info/RECORD"):  # keep RECORD true to the files
                data = b"".join(line + b"\n" for line in data.splitlines() if not line.decode().startswith(DROP))
            out.writestr(info, data)  # the same ZipInfo: executables keep their mode
    pruned.replace(wheel)
    print(f"{wheel}: {wheel.stat().st_size / 1e6:.1f} MB")
PY
ls -l "$dir"
