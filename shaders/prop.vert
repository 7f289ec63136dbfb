#version 450
#extension GL_GOOGLE_include_directive : require
#include "shared.h"

layout(push_constant) uniform Push { GpuPush pc; };

layout(location = 0) in vec3 in_position;  // metres, world
layout(location = 1) in vec3 in_normal;    // unit, world
layout(location = 2) in vec3 in_tangent;   // unit, world
layout(location = 3) in vec2 in_uv;

layout(location = 0) out vec3 out_position;
layout(location = 1) out vec3 out_normal;
layout(location = 2) out vec3 out_tangent;
layout(location = 3) out vec2 out_uv;

void main() {
    out_position = in_position;
    out_normal = in_normal;
    out_tangent = in_tangent;
    out_uv = in_uv;
    gl_Position = pc.clip_from_world * vec4(in_position, 1.0);
}
