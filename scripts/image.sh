#!/usr/bin/env bash
# Builds deploy/Dockerfile for real with podman, runs the container, uploads a
# clip and samples a pose from it, then prints the image's size and build time.
# No Docker engine or registry is needed: the two base images the Dockerfile
# names are made here with mmdebstrap from the machine's Debian mirror, the
# builder with this machine's own Rust toolchain copied in.
#
#   scripts/image.sh            # build, run, check; leaves the image `inbetween:latest`
#   scripts/image.sh --help     # this text
#
# Installs podman, runc and mmdebstrap with apt-get when they are missing.
# Environment: IMAGE (default inbetween:latest), KEEP_BASES=1 keeps the base
# images for the next run (they take about a minute to make).
set -euo pipefail
source "$(dirname "$0")/lib.sh"
ib_help "$@"
cd "$IB_ROOT"

IMAGE=${IMAGE:-inbetween:latest}
RUNTIME_BASE=localhost/inbetween-runtime-base:bookworm
BUILD_BASE=localhost/inbetween-build-base:bookworm
NAME=inbetween-image-check-$$

install_podman() {
  command -v podman >/dev/null && command -v mmdebstrap >/dev/null && command -v runc >/dev/null && return
  DEBIAN_FRONTEND=noninteractive apt-get update -q
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends podman runc mmdebstrap uidmap
}

# The sandbox cannot raise rlimits and crun refuses its hybrid cgroups.
configure_podman() {
  local conf=/etc/containers/containers.conf
  grep -q '^runtime = "runc"' "$conf" 2>/dev/null && return
  mkdir -p /etc/containers
  cat >>"$conf" <<'EOF'
[containers]
default_ulimits = ["nofile=20000:20000", "nproc=32768:32768"]
[engine]
runtime = "runc"
EOF
}

# The first `URIs:` of the machine's Debian sources: the mirror apt already uses.
debian_mirror() {
  awk '/^URIs:/ { print $2; exit }' /etc/apt/sources.list.d/debian.sources 2>/dev/null \
    || echo http://deb.debian.org/debian
}

# What debian:bookworm-slim leaves out: manuals, translations, documentation
# (licences kept), and apt's package lists.
SLIM=(
  --dpkgopt='path-exclude=/usr/share/man/*' --dpkgopt='path-exclude=/usr/share/locale/*'
  --dpkgopt='path-include=/usr/share/locale/locale.alias' --dpkgopt='path-exclude=/usr/share/doc/*'
  --dpkgopt='path-include=/usr/share/doc/*/copyright' --dpkgopt='path-exclude=/usr/share/info/*'
  --customize-hook='rm -rf "$1"/var/lib/apt/lists/* "$1"/var/cache/apt/*'
)

# A minbase Debian 12 root file system imported as an image, plus `$3` packages
# and the hook `$4` (mmdebstrap --customize-hook) when given.
make_base() {
  local tag=$1 tar=$2 include=$3 hook=${4:-true} env=${5:-}
  podman image exists "$tag" && return
  SOURCE_DATE_EPOCH=1700000000 mmdebstrap --quiet --variant=minbase ${include:+--include="$include"} \
    "${SLIM[@]}" --customize-hook="$hook" bookworm "$tar" "deb $(debian_mirror) bookworm main"
  podman import ${env:+--change "$env"} "$tar" "$tag" >/dev/null
  rm -f "$tar"
}

make_bases() {
  local tmp sysroot
  tmp=$(mktemp -d)
  sysroot=$(rustc --print sysroot)
  make_base "$RUNTIME_BASE" "$tmp/runtime.tar" ""
  # The toolchain without its documentation, at /usr/local/rust.
  make_base "$BUILD_BASE" "$tmp/build.tar" gcc,libc6-dev,ca-certificates \
    "mkdir -p \"\$1/usr/local/rust\" && tar -C '$sysroot' --exclude=share/doc -cf - . | tar -C \"\$1/usr/local/rust\" -xf -" \
    "ENV PATH=/usr/local/rust/bin:/usr/local/cargo/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin CARGO_HOME=/usr/local/cargo"
  rm -rf "$tmp"
}

# The host's CA bundle is mounted (not copied) so crates.io is reachable
# through this network's intercepting proxy; the image never holds it.
build_image() {
  local t0=$SECONDS
  podman build --pull=never --format docker -f deploy/Dockerfile -t "$IMAGE" \
    --build-arg RUST_IMAGE="$BUILD_BASE" --build-arg RUNTIME_IMAGE="$RUNTIME_BASE" \
    -v /etc/ssl/certs/ca-certificates.crt:/etc/ssl/certs/ca-certificates.crt:ro .
  BUILD_SECONDS=$((SECONDS - t0))
}

# Runs the image, waits for its healthcheck command, uploads
# examples/wave.json and checks the pose at t = 0.5 names both joints.
check_container() {
  local port id pose
  port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
  # No systemd here to time the healthcheck: it is run by hand below.
  podman run -d --rm --name "$NAME" --health-interval disable -p "127.0.0.1:$port:8080" "$IMAGE" >/dev/null
  trap 'podman rm -f "$NAME" >/dev/null 2>&1 || true' EXIT
  for _ in $(seq 50); do
    podman healthcheck run "$NAME" >/dev/null 2>&1 && break
    sleep 0.2
  done
  podman healthcheck run "$NAME" >/dev/null || { podman logs "$NAME"; return 1; }
  id=$(curl -sf -X POST "http://127.0.0.1:$port/v1/clips" -H 'Content-Type: application/json' \
    --data-binary @examples/wave.json | python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
  pose=$(curl -sf "http://127.0.0.1:$port/v1/clips/$id/pose?t=0.5")
  python3 -c 'import json,sys; p=json.loads(sys.argv[1]); assert [j["name"] for j in p["joints"]] == ["root","arm"], p' "$pose"
  echo "container: uploaded $id, pose at t=0.5: ${pose:0:120}…"
}

install_podman
configure_podman
make_bases
build_image
check_container
podman image prune -f >/dev/null
# Removing the builder base is tidying, not checking: a build stage's container
# (an "external" one, buildah's) has once still held it after the build returned,
# so it is removed by force, and a failure is reported rather than failing the run.
if [ "${KEEP_BASES:-}" != 1 ] && ! podman rmi --force "$BUILD_BASE" >/dev/null; then
  echo "warning: could not remove $BUILD_BASE; containers still on it:" >&2
  podman ps --all --external >&2 || true
fi
size=$(podman image inspect "$IMAGE" --format '{{.Size}}')
echo "image $IMAGE: $((size / 1000000)) MB, built in ${BUILD_SECONDS} s"
