#!/usr/bin/env bash
# Prepare the wheels a GPU machine without a registry needs for scripts/gpu_check.sh (docs/gpu.md,
# "Running the GPU check"), here, on a machine with pip and a registry:
#
#   1. download scripts/gpu_wheels.txt's pins for CPython 3.12 on manylinux x86_64 into .gpu/wheels;
#   2. check that they close: pip resolves morfic + its gpu extra for CPython 3.12 (online, metadata only,
#      torch standing in as the device's 2.11.0), every package is carried or on the device
#      (scripts/gpu_device_packages.txt), and again offline: --no-index against .gpu/wheels plus
#      metadata-only stubs of the device's packages picks every carried wheel;
#   3. tar the wheels (with their SHA256SUMS), split the tar into parts that fit one device call each
#      next to the working tree that travels anyway, one folder per call: .gpu/p1 .. .gpu/pN
#      (each with PARTS.sha256);
#   4. print the device calls (.gpu/PLAN.txt).
#
# Usage: bash scripts/gpu_wheels.sh [all|download|check|split|slim|full]   (default all; re-running reuses the downloads)
#        slim: leave artifacts/bundles/ (tens of MiB of shipped runs the check does not read) out of the working
#              tree with git sparse-checkout, so that the parts get the room; full: bring it back after the calls
#        PART_MIB=40 bash scripts/gpu_wheels.sh   (smaller parts than the limit allows; PART_SIZE=700 in bytes)
# .gpu/ (MORFIC_GPU_DIR) is git-ignored: nothing here is committed. Needs python3 with pip >= 23.2 and packaging.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
cd "$ROOT"
PY=${PYTHON:-python3}
G=${MORFIC_GPU_DIR:-.gpu}
WHAT=${1:-all}
TAGS=(--only-binary=:all: --python-version 3.12 --implementation cp --abi cp312
      --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64
      --platform manylinux2014_x86_64 --platform manylinux1_x86_64)
mkdir -p "$G/wheels" "$G/stubs"
# .gpu/ must never travel as untracked files (a checkout without this repo's .gitignore yet): exclude it here
if [ "${G#/}" = "$G" ] && ! git check-ignore -q "$G/wheels"; then
  echo "/${G#./}/" >> "$(git rev-parse --git-path info/exclude)"
  echo "added /${G#./}/ to $(git rev-parse --git-path info/exclude)"
fi

download() {
echo "== 1. download (CPython 3.12, manylinux x86_64) into $G/wheels"
grep -v '^#' scripts/gpu_wheels.txt | grep . > "$G/pins.txt"
"$PY" -m pip download -q --no-deps "${TAGS[@]}" -d "$G/wheels" -r "$G/pins.txt"
# keep exactly the pinned files (an earlier pin's wheel would make two versions of one package)
"$PY" - "$G/wheels" "$G/pins.txt" <<'EOF'
import sys
from pathlib import Path
from packaging.utils import canonicalize_name, parse_wheel_filename
wheels, pins = Path(sys.argv[1]), {}
for line in Path(sys.argv[2]).read_text().split():
    name, version = line.split("==")
    pins[canonicalize_name(name)] = version
for whl in sorted(wheels.glob("*.whl")):
    name, version, _, _ = parse_wheel_filename(whl.name)
    if pins.get(name) != str(version):
        print(f"removing {whl.name} (not pinned)")
        whl.unlink()
EOF
(cd "$G/wheels" && ls -l --block-size=1 *.whl | awk '{printf "  %10.1f MiB  %s\n", $5 / 1048576, $9}')
}

check() {
echo "== 2. resolution check for CPython 3.12"
TORCH_STUB=$("$PY" -c "
import sys; sys.path.insert(0, 'scripts')
from pathlib import Path
from gpu_wheels import write_stub
print(write_stub(Path('$G/stubs'), 'torch', '2.11.0', [], '>=3.10').resolve())")
"$PY" -c "
import tomllib
p = tomllib.load(open('pyproject.toml', 'rb'))['project']
print('\n'.join(r for r in p['dependencies'] + p['optional-dependencies']['gpu'] if not r.startswith('torch')))
" > "$G/requirements.txt"
echo "torch @ file://$TORCH_STUB" >> "$G/requirements.txt"
# online, metadata only: what would a CPython 3.12 install of morfic[gpu] take, with the carried pins?
"$PY" -m pip install -q --dry-run --ignore-installed --target "$G/dry-run-target" "${TAGS[@]}" -c "$G/pins.txt" -r "$G/requirements.txt" \
  --report "$G/resolve-online.json"
"$PY" scripts/gpu_wheels.py stubs "$G/resolve-online.json" "$G/stubs"
# offline: the carried wheels plus the device's packages (stubs), nothing else
"$PY" -m pip install -q --dry-run --ignore-installed --target "$G/dry-run-target" --no-index --find-links "$G/wheels" --find-links "$G/stubs" \
  "${TAGS[@]}" -r "$G/requirements.txt" --report "$G/resolve-offline.json"
"$PY" scripts/gpu_wheels.py verify "$G/resolve-offline.json" "$G/wheels"
}

tree_bytes() {  # tracked and untracked-not-ignored files present here (a sparse checkout's left-out ones don't travel)
{ git ls-files -z -c -o --exclude-standard | xargs -0 stat -c %s 2>/dev/null || true; } | awk '{s += $1} END {print s + 0}'
}

split_parts() {
echo "== 3. split into parts that fit a device call"
# what travels with every call: tracked and untracked-not-ignored files (and shared/ if the checkout has one)
TREE_BYTES=$(tree_bytes)
[ -d shared ] && TREE_BYTES=$((TREE_BYTES + $(du -sb shared | cut -f1)))
LIMIT_MIB=$(( (64 * 1048576 - TREE_BYTES) / 1048576 - 2 ))  # 2 MiB margin for the part folders' small files
PART_MIB=${PART_MIB:-$LIMIT_MIB}
[ "$PART_MIB" -gt "$LIMIT_MIB" ] && PART_MIB=$LIMIT_MIB
if [ "$PART_MIB" -lt 8 ]; then
  echo "Error: the working tree ($((TREE_BYTES / 1048576)) MiB) leaves no room for parts;" \
    "run 'bash scripts/gpu_wheels.sh slim' to leave artifacts/bundles/ out of it, then split again" >&2
  exit 1
fi
PART_SIZE=${PART_SIZE:-${PART_MIB}M}
(cd "$G/wheels" && sha256sum *.whl > SHA256SUMS)
rm -rf "$G"/p[0-9]* "$G/split"
mkdir -p "$G/split"
tar -C "$G" -cf - wheels/SHA256SUMS $(cd "$G" && ls wheels/*.whl) | split -b "$PART_SIZE" -d -a 2 - "$G/split/morfic-wheels.tar."
(cd "$G/split" && sha256sum morfic-wheels.tar.* > PARTS.sha256)
k=0
folders=()
for part in "$G"/split/morfic-wheels.tar.*; do
  k=$((k + 1))
  mkdir -p "$G/p$k"
  mv "$part" "$G/p$k/"
  cp "$G/split/PARTS.sha256" "$G/p$k/"
  folders+=("$G/p$k")
done
rm -rf "$G/split"
echo "  $k parts (split -b $PART_SIZE); working tree $(awk -v b="$TREE_BYTES" 'BEGIN {printf "%.1f", b / 1048576}') MiB"

echo "== 4. the device calls (each within ~30 s of the last: the machine keeps the parts only while warm)"
"$PY" scripts/gpu_wheels.py plan "$TREE_BYTES" "${folders[@]}" | tee "$G/PLAN.txt"
}

BUNDLES=artifacts/bundles
slim() {
echo "== leave $BUNDLES/ out of the working tree (git sparse-checkout; 'full' brings it back)"
git sparse-checkout set --no-cone '/*' "!/$BUNDLES/"
echo "  $BUNDLES/ is out; a device call now carries a $(tree_bytes | awk '{printf "%.1f", $1 / 1048576}') MiB tree"
}
full() {
echo "== bring $BUNDLES/ back into the working tree"
git sparse-checkout disable
}

case "$WHAT" in
  all) download; check; split_parts ;;
  download) download ;;
  check) check ;;
  split) split_parts ;;
  slim) slim ;;
  full) full ;;
  *) echo "usage: bash scripts/gpu_wheels.sh [all|download|check|split|slim|full]" >&2; exit 2 ;;
esac
