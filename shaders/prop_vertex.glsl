// The prop's vertex stage (prop.vert; multiview.vert with HS_MULTIVIEW: every view of a
// multiview pass runs each draw, and a draw meant for one view (push constants'
// light_mask.z) puts its triangles outside the clip volume in the others, so each view gets
// exactly the draws of its own pass). A device with multiview runs multiview.vert in every
// pipeline, passes of one view included (gl_ViewIndex 0, light_mask.z 0), so that a layer's
// positions come from one shader whichever way its eyes are drawn.
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
#ifdef HS_MULTIVIEW
    // Beyond x = w for every vertex: the whole triangle is clipped away.
    if (uint(gl_ViewIndex) != pc.light_mask.z)
        gl_Position = vec4(2.0, 0.0, 0.5, 1.0);
#endif
}
