#!/usr/bin/env bash
# The test command of the README: checks formatting and lints (rustfmt,
# clippy), installs what the tests need (POV-Ray 3.7 and
# python3 for the oracle comparison, Debian's assimp test models for the mesh
# importer corpus, GNU time for the hostile tests' memory bounds) when they are
# missing, then runs every test of the workspace, then the embedding examples,
# then the one-node Slurm test of split rendering (scripts/slurm/test.sh).
set -euo pipefail
cd "$(dirname "$0")/.."

need=()
command -v povray >/dev/null 2>&1 || need+=(povray)
command -v python3 >/dev/null 2>&1 || need+=(python3)
[ -d /usr/share/assimp/models ] || need+=(assimp-testmodels)
[ -x /usr/bin/time ] || need+=(time)
if [ ${#need[@]} -gt 0 ]; then
  echo "scripts/test.sh: installing ${need[*]} (Debian packages)"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq || true
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need[@]}" >/dev/null || {
    echo "scripts/test.sh: could not install ${need[*]}; the POV-Ray test will fail (ROTHRAY_SKIP_POVRAY=1 skips it)" >&2
  }
fi

# Formatting and lints first (cheap, and they fail fast). The components come
# with rustup when the toolchain lacks them.
for c in rustfmt clippy; do
  if ! cargo "$( [ $c = rustfmt ] && echo fmt || echo clippy )" --version >/dev/null 2>&1; then
    echo "scripts/test.sh: installing the $c component (rustup)"
    rustup component add "$c"
  fi
done
cargo fmt --check
cargo clippy --workspace --all-targets --release -- -D warnings

# Release-mode tests: the oracles trace tens of thousands of rays.
cargo test --workspace --release "$@"

# The embedding examples of the README (quick: seconds each).
cargo run --release --example pick
cargo run --release --example mesh_cut
cargo run --release --example live

# A real scheduler: a one-node Slurm runs a split render as a job array plus a
# merge job, compared byte for byte with a single render (needs root; installs
# slurm-wlm and munge when missing; ROTHRAY_SKIP_SLURM=1 skips it).
if [ "${ROTHRAY_SKIP_SLURM:-0}" != 1 ]; then
  scripts/slurm/test.sh
fi
