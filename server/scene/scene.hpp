// The scene model: pure data, no GPU and no file formats. Units: metres, radians unless a name
// says _deg. World frame: right-handed, +y up, the floor at y = 0.
// Every camera-like frame (projector, head, eye) is x right, y up, looking along -z (the glTF and
// OpenXR convention); a Pose maps that frame to the world (T_world_frame).
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <glm/gtc/quaternion.hpp>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>
#include <glm/vec4.hpp>

#include "core/image.hpp"

namespace hs::scene {

struct Pose {
    glm::dvec3 position{0.0};            // metres, world frame
    glm::dquat orientation{1, 0, 0, 0};  // unit quaternion, world from frame (w, x, y, z)
};

// Pinhole intrinsics in the OpenCV convention: u right, v down, pixel centres at integers.
struct Intrinsics {
    uint32_t width = 0;     // pixels
    uint32_t height = 0;    // pixels
    double fx = 0, fy = 0;  // focal lengths, pixels
    double cx = 0, cy = 0;  // principal point, pixels
};

enum class SpecularModel { kNone = 0, kPhong = 1, kBlinnPhong = 2, kWard = 3, kKajiyaKay = 4 };
const char* to_string(SpecularModel model);

struct Specular {
    SpecularModel model = SpecularModel::kNone;
    glm::dvec3 colour{0.0};  // k_s (Phong, Blinn, Kajiya-Kay) or rho_s (Ward), linear RGB
    double exponent = 1.0;   // Phong, Blinn-Phong, Kajiya-Kay: cosine exponent, >= 1
    double alpha_x = 0.2;    // Ward: RMS slope along the tangent, > 0
    double alpha_y = 0.2;    // Ward: RMS slope along the bitangent, > 0
    // Ward and Kajiya-Kay: the surface tangent is this world direction projected onto the
    // tangent plane (brushing direction); where it is parallel to the normal a fixed fallback
    // perpendicular is used (docs/SHADING.md).
    glm::dvec3 tangent_axis{1.0, 0.0, 0.0};
    // Where t comes from: kAxis projects tangent_axis; kMesh uses the mesh's tangents (glTF
    // TANGENT, or the hemisphere's azimuthal direction: a lathe-turned finish), orthogonalised
    // against the normal.
    enum class TangentSource { kAxis, kMesh } tangent_source = TangentSource::kAxis;

    bool uses_tangent() const { return model == SpecularModel::kKajiyaKay || anisotropic(); }
    bool anisotropic() const { return model == SpecularModel::kWard && alpha_x != alpha_y; }
};

struct Material {
    glm::dvec3 albedo{
        0.8};  // diffuse reflectance rho_d in [0, 1], linear RGB (Lambert: rho_d / pi)
    // Optional sRGB-encoded texture multiplying `albedo`, sampled at the mesh UVs: bilinear,
    // repeating in u, clamped in v (docs/SHADING.md). Null when the material has none.
    std::shared_ptr<const ImageRgba8> albedo_texture;
    std::string albedo_texture_path;
    Specular specular;
    glm::dvec3 emission{0.0};  // L_e, radiance added to the VD layer, linear RGB
};

enum class LightType { kDirectional, kPoint, kRect };

struct Light {
    LightType type = LightType::kDirectional;
    glm::dvec3 colour{1.0};          // linear RGB, multiplies intensity
    double intensity = 1.0;          // directional: irradiance W/m^2 at normal incidence;
                                     // point: radiant intensity W/sr; rect: radiant intensity
                                     // W/sr along the panel's normal (a Lambertian emitter)
    glm::dvec3 direction{0, -1, 0};  // directional: unit direction the light travels, world
    glm::dvec3 position{0.0};        // point: metres, world; rect: the panel's centre
    // rect: the panel's two edges (metres, world). It emits from the side edge_u x edge_v
    // points to, with radiance intensity / area (docs/SHADING.md, "Area lights").
    glm::dvec3 edge_u{0.0}, edge_v{0.0};
};

// Where the point-light falloff 1/d^2 is evaluated with d clamped from below (docs/SHADING.md).
inline constexpr double kMinLightDistance = 1e-3;  // metres

struct Mesh {
    std::vector<glm::vec3> positions;  // metres, world frame
    std::vector<glm::vec3> normals;    // unit, world frame, one per position
    std::vector<glm::vec2> uvs;        // one per position
    std::vector<glm::vec3> tangents;   // unit, world frame, one per position (glTF TANGENT.xyz,
                                       // the hemisphere's azimuthal direction, or +x if absent)
    std::vector<uint32_t> indices;     // triangle list, counter-clockwise seen from outside
    uint32_t dropped_triangles = 0;    // degenerate triangles removed while loading
    bool empty() const { return indices.empty(); }
};

struct Hemisphere {
    glm::dvec3 centre{0.0, 0.695, 0.0};  // centre of the flat base, metres, world
    double radius = 0.15;                // metres
    uint32_t segments = 256;             // tessellation around the vertical axis, >= 3
    uint32_t rings = 64;                 // tessellation from the pole to the base, >= 1
};

struct Prop {
    enum class Kind { kHemisphere, kGltf } kind = Kind::kHemisphere;
    Hemisphere hemisphere;  // kind == kHemisphere: the exact shape, dome up (+y)
    std::string gltf_path;  // kind == kGltf: absolute, or resolved against the scene file
    glm::dvec3 gltf_translation{0.0};  // metres, applied after the glTF's own node transforms
    double gltf_scale = 1.0;
    // kind == kGltf: the mesh as parse_scene loaded it (transformed, not yet cleaned), so the
    // file is read and checked once, at parse time. Null: build_prop_mesh loads gltf_path.
    std::shared_ptr<const Mesh> gltf_mesh;
};

struct Projector {
    std::string name;
    Intrinsics intrinsics;
    Pose pose;  // T_world_projector
    // This projector's measured levels (camera DN/s, as DeviceLevels): its response to a full
    // drive (P^M) and its black level (P^m). Unset: the scene's optics.levels.
    std::optional<double> white_level, black_level;
};

// An optical see-through headset's display, one eye. Eyes are at -ipd/2 and +ipd/2 along the
// head's x axis; both share these intrinsics.
struct ViewerProfile {
    std::string name;
    uint32_t eye_width = 0;   // pixels
    uint32_t eye_height = 0;  // pixels
    double fov_x_rad = 0;     // full horizontal field of view
    double fov_y_rad = 0;     // full vertical field of view
    bool has_intrinsics =
        false;              // true: `intrinsics` below, not the fields of view, define the eye
    Intrinsics intrinsics;  // per-eye pinhole intrinsics (pixels), when has_intrinsics
    double ipd_m = 0.063;   // interpupillary distance
    double alpha = 1.0;     // transparency of the optics in [0, 1] (paper eq. 3)
};

// The ranges of Viewing's numbers, where scenes and command lines give them.
inline constexpr double kMaxViewAngleDeg = 360.0;  // |angle| about +y
inline constexpr double kMaxViewHeightM = 1e4;     // |eye height| above the floor, metres

// How `hysar render` places viewers, as in the paper's Fig. 7 (scene::viewing_pose).
struct Viewing {
    glm::dvec3 target{0.0, 0.745, 0.0};  // the point every viewer looks at, metres, world
    double distance_m = 0.8;             // horizontal distance from target
    std::vector<double> angles_deg{-40, -20, 0, 20, 40};  // azimuth about +y, 0 = from +z
    std::map<std::string, double> heights_m{{"H", 1.35}, {"M", 1.10}, {"L", 0.90}};
    std::string default_height = "M";
};

struct Effects {
    bool point_light_falloff = true;  // 1/d^2 for point lights; off makes them constant irradiance
    // The headsets' fill-in (docs/OPTICS.md, "Fill-in"): surface a viewer sees but no projector
    // reaches gets its VI part in the viewer's VD layer. On by default; it costs nothing where
    // the projectors reach everything a viewer sees.
    bool headset_fill = true;
};

// Device levels as a user-perspective camera measures them (paper Sec. 4.4): mean camera value
// of a region of interest at the prop's centre, scaled to a 1 s exposure (camera DN per second).
struct DeviceLevels {
    double projector_max = 2053.0;  // P^M: projector white on the prop (reference white albedo)
    double projector_min = 2053.0 / 61.0;  // P^m: projector black level
    double hmd_max = 3539.0;               // H^M: headset white, seen through its optics
    double hmd_min = 3539.0 / 193.0;       // H^m: headset black level
    double environment = 0.0;              // E: room light reflected by the prop, without the HMD
};

// The capture simulation (docs/OPTICS.md): what a camera behind the headset records. Every
// effect is switched here; a switched-off effect is not computed.
struct Optics {
    DeviceLevels levels;
    glm::dvec3 prop_albedo{0.92, 0.90, 0.86};  // the white prop's albedo relative to the white
                                               // on which projector_max was measured
    double prop_sheen = 0.0;                   // specular reflectance of the prop (vinyl sheen)
    double prop_sheen_exponent = 30.0;         // its Phong exponent
    double exposure_ms = 125.0;                // camera exposure time
    uint32_t bits = 8;                         // camera bit depth (linear response)
    double noise_dn = 0.0;                     // camera read noise, standard deviation in DN
    double scene_to_signal = 0.0;  // k: camera DN/s per unit scene radiance; 0 picks the largest
                                   // k the projector can show (docs/OPTICS.md)
    struct Effects {
        bool projector_falloff = true;  // cos(theta) / d^2 of the projector's light
        bool black_levels = true;       // P^m and H^m
        bool environment = true;        // E (a no-op when levels.environment is 0)
        bool prop_albedo = true;        // the prop's tint
        bool prop_sheen = true;         // the sheen (a no-op when prop_sheen is 0)
        bool saturation = true;         // clipping at the camera's full scale
        bool quantisation = true;       // integer camera values
    } effects;
    struct Compensation {  // what the projector and headset images correct for
        bool falloff = true;
        bool albedo = true;
        bool hmd_alpha = true;  // the VD layer dimmed by alpha to match the see-through view
        bool black_levels = true;
    } compensation;
};

// A material captured from a real object (docs/CALIBRATION.md): instead of rendering, the
// projector shows a calibrated "VI" image and a headset near the capture pose gets the
// calibrated "VD" image (both eyes: the capture is monocular). Both images are device drives
// in [0, 1] (what the device is sent), at the projector's and the headset display's size.
struct CapturedMaterial {
    std::string projector_image_path;  // OpenEXR, projector size
    std::string viewer_image_path;     // OpenEXR, the headset display's size
    std::shared_ptr<const ImageRgba32f> projector_image, viewer_image;
    Pose capture_head;  // the head pose the VD image was made for
    double position_tolerance_m = 0.05;
    double angle_tolerance_deg = 5.0;
};

struct Scene {
    int schema_version = 1;
    std::string name;
    Prop prop;
    Material material;
    std::map<std::string, Specular> specular_presets;  // named alternatives (Fig. 7 rows)
    std::vector<Light> lights;
    // The installation's projectors (docs/SCENE_FORMAT.md, `projectors`): `projector` is the
    // first, `more_projectors` the others in the scene's order (empty: one projector, the
    // single-projector path unchanged). Names are unique. projectors() lists all of them.
    Projector projector;
    std::vector<Projector> more_projectors;
    std::vector<ViewerProfile> viewers;  // at least one
    Viewing viewing;
    Effects effects;
    Optics optics;
    std::optional<CapturedMaterial> captured_material;

    const ViewerProfile* find_viewer(const std::string& name) const;
    // Every projector, the first one first.
    std::vector<Projector> projectors() const;
    size_t projector_count() const { return 1 + more_projectors.size(); }
};

inline constexpr int kSchemaVersion = 1;
inline constexpr size_t kMaxLights = 64;
inline constexpr size_t kMaxProjectors = 16;

}  // namespace hs::scene
