#version 450
#extension GL_GOOGLE_include_directive : require
#include "shared.h"

// Evaluates the exact GLSL shading functions at given vectors, for the hard-case tests and
// `hysar bench stability`: the specular factor and diffuse cosine at (n, l, v), and one light's
// diffuse and specular radiance through the fragment shader's light, falloff and half-float
// layer code.
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
    vec3 n = c.n.xyz, v = c.v.xyz;
    vec3 l, E;
    hs_light(c.l, vec3(c.material.x), c.p.xyz, n, c.params.w, true, l, E);
    float s = hs_specular_factor(kSpecModel, kAnisotropic, n, l, v, c.t.xyz, c.params.xyz);
    float cos_l = max(dot(n, l), 0.0);
    float ld = c.material.y * (E.x * cos_l);
    float ls = c.material.z * (E.x * s);
    vec3 half_layer = unpackHalf2x16(packHalf2x16(hs_half_layer(vec3(ld, ls, 0.0)).xy)).xyy;
    results[i].value = vec4(s, cos_l, 0.0, 0.0);
    results[i].radiance = vec4(ld, ls, half_layer.x, half_layer.y);
}
