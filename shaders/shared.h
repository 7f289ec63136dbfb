// Buffer layouts, bindings and limits shared by GLSL and C++ (std140 / std430 compatible:
// every member is a vec4 or mat4). C++ static_asserts the sizes in gpu/shared_layout.hpp.
#ifndef HYSAR_SHADERS_SHARED_H
#define HYSAR_SHADERS_SHARED_H

#ifdef __cplusplus
#include <cstdint>
#include <glm/ext/vector_uint4.hpp>
#include <glm/mat4x4.hpp>
#include <glm/vec4.hpp>
namespace hs::gpu_shared {
using vec4 = glm::vec4;
using mat4 = glm::mat4;
using uint = uint32_t;
using uvec4 = glm::uvec4;
#endif

#define HS_MAX_LIGHTS 64
#define HS_BINDING_SCENE 0
#define HS_BINDING_ALBEDO_TEXTURE 1
#define HS_BINDING_FILL 2  // the headsets' fill-in: the projectors' shadow maps (an R32F atlas)
#define HS_MAX_FILL_PROJECTORS 16  // scene::kMaxProjectors
#define HS_BINDING_PROBE_IN 0
#define HS_BINDING_PROBE_OUT 1
#define HS_PROBE_LOCAL_SIZE 64
#define HS_TILES_LOCAL_SIZE 64  // tiles.comp: invocations per workgroup

// Specialization constant ids (gpu/shared_layout.hpp mirrors them as an enum).
#define HS_SC_PASS_KIND \
    0  // 0: projector VI pass (diffuse), 1: viewer VD pass (specular + emission),
       // 2: capture geometry (where each camera pixel meets the projector; docs/OPTICS.md),
       // 3: occluder (writes black: a cluster that cannot light a VD layer but may hide one)
#define HS_SC_SPEC_MODEL \
    1  // scene::SpecularModel: 0 none, 1 phong, 2 blinn-phong, 3 ward, 4 kajiya-kay
#define HS_SC_EMISSION 2        // bool: add the material's emission
#define HS_SC_POINT_FALLOFF 3   // bool: 1/d^2 for point lights
#define HS_SC_NUM_LIGHTS 4      // int: number of lights read from the scene block
#define HS_SC_OUTPUT_MAX 5      // float: clamp of written radiance (65504 for 16-bit float targets)
#define HS_SC_ANISOTROPIC 6     // bool: Ward with alpha_x != alpha_y (needs the tangent frame)
#define HS_SC_MESH_TANGENT 7    // bool: the tangent comes from the mesh, not from tangent_axis
#define HS_SC_ALBEDO_TEXTURE 8  // bool: albedo = colour * texture(uv)
#define HS_SC_PROP_SHEEN 9      // bool: capture geometry also writes the prop's sheen lobe
#define HS_SC_AREA_SAMPLES 10   // int: samples per rect light per pixel; 0: the scene has none
#define HS_SC_OUTPUT_ENCODING \
    11  // 0: linear radiance (clamped to OUTPUT_MAX), 1: a VD layer's sRGB8 codes into an RGBA8
        // target, 2: a VD layer's half floats into an RGBA16F target. 1 and 2 write what the
        // wire carries (PROTOCOL.md, VdLayer): alpha 0 exactly where the colour is 0
#define HS_SC_ANALYTIC_SPHERE \
    12  // bool: the prop is prop_sphere's dome: each pixel shades the
        // exact point its ray hits, with the sphere's normal, UV and
        // tangent there; the tessellation only decides coverage
#define HS_SC_LIGHTS_LO \
    13  // uint: VD pass, bit i (of lights 0..31) clear: light i is compiled out. All ones: the
        // push constants' light_mask decides per draw instead (one pipeline for every mask)
#define HS_SC_LIGHTS_HI 14  // uint: the same for lights 32..63
#define HS_SC_LOBE_EXPONENT \
    15  // int: the lobe exponent when it is a whole number in 1..4095 (x^e by squaring, exact
        // to a few ulp and without pow's exp2/log2); 0: pow with the scene block's exponent
#define HS_SC_FILL \
    16  // int: VD pass, the headsets' fill-in (docs/OPTICS.md, "Fill-in") over this many
        // projectors of the fill block (0: off): where none reaches the shaded point, the VI
        // term is added too; -1: added everywhere, untested (clusters facing away from every
        // projector). A constant count lets the loop unroll, so that the projectors'
        // parameters are read at constant offsets (one load for all lanes, not one per lane)

struct GpuLight {
    vec4 position_or_direction;  // xyz: point position or rect centre (m, world), or unit
                                 // direction TO the light; w: 1 point, 0 directional, 2 rect
    vec4 irradiance;  // rgb: colour * intensity (W/m^2 at normal incidence, or W/sr for points
                      // and along a rect's normal)
    vec4 edge_u;      // rect: xyz the first edge (m, world)
    vec4 edge_v;      // rect: xyz the second edge; the panel emits towards edge_u x edge_v
};

// One projector as the fill-in's coverage test sees it (render/blend.hpp's V_j): the point must
// project inside its frame, face it, and not lie behind the surfaces of its shadow map. The
// shadow maps lie side by side in one R32F texture (HS_BINDING_FILL): per pixel the distance
// along the projector's axis to the nearest prop surface, +FLT_MAX where none.
struct GpuFillProjector {
    mat4 frame_from_world;  // the projector frame (x right, y up, looking along -z)
    vec4 k;                 // fx, fy, cx, cy in pixels (OpenCV convention)
    vec4 position;          // xyz: projector centre, metres, world; w: shadow bias in pixels
    uvec4 size;             // x width, y height; z, w: its shadow map's corner in the atlas
};

struct GpuScene {
    vec4 albedo_over_pi;  // rgb: rho_d / pi
    vec4 spec_colour;     // rgb: k_s or rho_s
    vec4 spec_params;     // x: exponent, y: alpha_x, z: alpha_y, w: min light distance (m)
    vec4 tangent_axis;    // xyz: unit world axis projected to the tangent plane
    vec4 emission;        // rgb: L_e
    GpuLight lights[HS_MAX_LIGHTS];
    // Capture geometry pass only (pass kind 2): the projector as a pinhole.
    mat4 projector_frame_from_world;  // the projector frame (x right, y up, looking along -z)
    vec4 projector_k;                 // fx, fy, cx, cy in pixels (OpenCV convention)
    vec4 projector_position;          // xyz: projector centre, metres, world
    vec4 sheen_params;                // x: Phong exponent of the prop's sheen
    vec4 prop_sphere;  // xyz: the analytic prop's sphere centre (m, world), w: its radius
    // The headsets' fill-in (VD pass with HS_SC_FILL projectors): the first HS_SC_FILL.
    GpuFillProjector fill_projectors[HS_MAX_FILL_PROJECTORS];
};

struct GpuPush {
    mat4 clip_from_world;  // Vulkan clip space from world (scene/camera.hpp)
    vec4 eye_position;     // xyz: viewer eye (VD pass) in metres, world
    vec4 camera_position;  // xyz: the camera this pass renders from (rays start here), world
    uvec4 light_mask;      // VD pass: bit i of (x, y) set: light i may add light to this draw;
                           // z: in a multiview pass, the view this draw is for
};

// One shading probe: evaluates shaders/shading.glsl at given vectors (tests of hard cases).
struct GpuProbeCase {
    vec4 n;         // xyz unit normal
    vec4 l;         // xyz unit direction to the light (w = 0), or a point light's position (w = 1)
    vec4 v;         // xyz unit direction to the viewer
    vec4 t;         // xyz tangent axis (projected to the plane of n in the shader)
    vec4 params;    // x exponent, y alpha_x, z alpha_y, w min light distance (m)
    vec4 p;         // xyz surface point (for a point light)
    vec4 material;  // x irradiance (direction) or intensity (point), y albedo / pi, z k_s
};
struct GpuProbeResult {
    vec4 value;     // x: specular factor (S n.l, or W), y: diffuse cosine max(n.l, 0)
    vec4 radiance;  // x: L_d, y: L_s in fp32; z, w: the same as a half-float layer stores them
};

#ifdef __cplusplus
}  // namespace hs::gpu_shared
#endif

#endif
