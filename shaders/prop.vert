#version 450
#extension GL_GOOGLE_include_directive : require
#include "shared.h"

layout(push_constant) uniform Push { GpuPush pc; };

layout(location = 0) in vec3 in_position;  // metres, world
layout(location = 1) in vec3 in_normal;    // unit, world

layout(location = 0) out vec3 out_position;
layout(location = 1) out vec3 out_normal;

void main() {
    out_position = in_position;
    out_normal = in_normal;
    gl_Position = pc.clip_from_world * vec4(in_position, 1.0);
}
