#!/usr/bin/env bash
# Set-up, then the main job on the embedded default scene: the projector frame, the VD layers
# of the paper's Fig. 7 viewpoints for every specular model, a contact sheet and render.json.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
./build/hysar render --out out/render "$@"
echo "demo: open out/render/sheet.png (Fig. 7 layout) and out/render/projector.png; figures in out/render/render.json"
