// The C++ side of shaders/shared.h, with the size checks that keep both sides in step.
#pragma once

#include "shaders/shared.h"

namespace hs::gpu {
using gpu_shared::GpuFillProjector;
using gpu_shared::GpuLight;
using gpu_shared::GpuProbeCase;
using gpu_shared::GpuProbeResult;
using gpu_shared::GpuPush;
using gpu_shared::GpuScene;

static_assert(sizeof(GpuLight) == 64, "GpuLight must match std140 layout");
static_assert(sizeof(GpuScene) ==
                  5 * 16 + HS_MAX_LIGHTS * 64 + 64 + 4 * 16 + HS_MAX_FILL_PROJECTORS * 112,
              "GpuScene must match std140 layout");
static_assert(sizeof(GpuFillProjector) == 112, "GpuFillProjector must match std140 layout");
static_assert(sizeof(GpuPush) == 112, "GpuPush must match the push constant block");
static_assert(sizeof(GpuPush) <= 128, "push constants must fit the guaranteed 128 bytes");
static_assert(sizeof(GpuProbeCase) == 112, "GpuProbeCase must match std430 layout");
static_assert(sizeof(GpuProbeResult) == 32, "GpuProbeResult must match std430 layout");
}  // namespace hs::gpu
