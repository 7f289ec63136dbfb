#version 450
#extension GL_GOOGLE_include_directive : require
#include "shared.h"

// Evaluates the exact GLSL shading functions at given vectors, for the hard-case tests.
layout(constant_id = HS_SC_SPEC_MODEL) const int kSpecModel = 1;
layout(constant_id = HS_SC_ANISOTROPIC) const bool kAnisotropic = false;
layout(local_size_x = HS_PROBE_LOCAL_SIZE) in;

layout(std430, set = 0, binding = HS_BINDING_PROBE_IN) readonly buffer In { GpuProbeCase cases[]; };
layout(std430, set = 0, binding = HS_BINDING_PROBE_OUT) writeonly buffer Out { GpuProbeResult results[]; };
layout(push_constant) uniform Push { uint count; } pc;

#include "shading.glsl"

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.count) return;
    GpuProbeCase c = cases[i];
    float s = hs_specular_factor(kSpecModel, kAnisotropic, c.n.xyz, c.l.xyz, c.v.xyz, c.t.xyz, c.params.xyz);
    results[i].value = vec4(s, max(dot(c.n.xyz, c.l.xyz), 0.0), 0.0, 0.0);
}
