#include "scene/config.hpp"

#include <cmath>
#include <cstring>
#include <fstream>
#include <optional>
#include <set>
#include <sstream>

#include <fmt/format.h>
#include <glm/geometric.hpp>
#include <glm/trigonometric.hpp>
#include <nlohmann/json.hpp>

#include "core/check.hpp"
#include "scene/assets.hpp"
#include "scene/camera.hpp"
#include "scene/json_limits.hpp"
#include "scene/mesh.hpp"

namespace hs::scene {

using json = nlohmann::json;

const char* to_string(SpecularModel m) {
    switch (m) {
        case SpecularModel::kNone:
            return "none";
        case SpecularModel::kPhong:
            return "phong";
        case SpecularModel::kBlinnPhong:
            return "blinn-phong";
        case SpecularModel::kWard:
            return "ward";
        case SpecularModel::kKajiyaKay:
            return "kajiya-kay";
    }
    return "?";
}

Result<SpecularModel> parse_specular_model(std::string_view s) {
    if (s == "none")
        return SpecularModel::kNone;
    if (s == "phong")
        return SpecularModel::kPhong;
    if (s == "blinn-phong")
        return SpecularModel::kBlinnPhong;
    if (s == "ward")
        return SpecularModel::kWard;
    if (s == "kajiya-kay")
        return SpecularModel::kKajiyaKay;
    return make_error(ErrorCode::kInvalidArgument,
                      fmt::format("unknown specular model '{}' (expected none, phong, blinn-phong, "
                                  "ward or kajiya-kay)",
                                  s));
}

std::vector<Projector> Scene::projectors() const {
    std::vector<Projector> all{projector};
    all.insert(all.end(), more_projectors.begin(), more_projectors.end());
    return all;
}

const ViewerProfile* Scene::find_viewer(const std::string& n) const {
    for (const auto& v : viewers)
        if (v.name == n)
            return &v;
    return nullptr;
}

namespace {

// Reads typed values out of JSON, keeping the first error with its file and key path.
class Reader {
public:
    explicit Reader(std::string source) : source_(std::move(source)) {}

    bool failed() const { return error_.has_value(); }
    Error error() const { return *error_; }

    void fail(const std::string& path, const std::string& what) {
        if (!error_)
            error_ = make_error(ErrorCode::kParse, fmt::format("{}: {}: {}", source_, path, what));
    }

    // Rejects keys outside `allowed`, so a misspelt key is an error rather than silently ignored.
    void only(const json& obj, const std::string& path,
              std::initializer_list<const char*> allowed) {
        if (!obj.is_object())
            return;
        std::set<std::string> ok(allowed.begin(), allowed.end());
        for (auto it = obj.begin(); it != obj.end(); ++it) {
            if (!ok.count(it.key())) {
                std::string list;
                for (const char* a : allowed) list += std::string(list.empty() ? "" : ", ") + a;
                fail(join(path, it.key()), fmt::format("unknown key (expected one of: {})", list));
            }
        }
    }

    const json* member(const json& obj, const std::string& path, const char* key, bool required) {
        if (!obj.is_object()) {
            fail(path, fmt::format("expected an object, got {}", obj.type_name()));
            return nullptr;
        }
        auto it = obj.find(key);
        if (it == obj.end()) {
            if (required)
                fail(join(path, key), "missing required key");
            return nullptr;
        }
        return &*it;
    }

    double number(const json& obj, const std::string& path, const char* key,
                  std::optional<double> def, double lo, double hi) {
        const json* v = member(obj, path, key, !def.has_value());
        if (!v)
            return def.value_or(0.0);
        if (!v->is_number()) {
            fail(join(path, key), fmt::format("expected a number, got {}", v->type_name()));
            return def.value_or(0.0);
        }
        double x = v->get<double>();
        if (!std::isfinite(x) || x < lo || x > hi) {
            fail(join(path, key), fmt::format("expected a number in [{}, {}], got {}", lo, hi, x));
        }
        return x;
    }

    uint32_t integer(const json& obj, const std::string& path, const char* key,
                     std::optional<uint32_t> def, uint32_t lo, uint32_t hi) {
        const json* v = member(obj, path, key, !def.has_value());
        if (!v)
            return def.value_or(0);
        if (!v->is_number_integer() || v->get<int64_t>() < int64_t(lo) ||
            v->get<int64_t>() > int64_t(hi)) {
            fail(join(path, key),
                 fmt::format("expected an integer in [{}, {}], got {}", lo, hi, brief_json(*v)));
            return def.value_or(lo);
        }
        return uint32_t(v->get<int64_t>());
    }

    glm::dvec3 vec3(const json& obj, const std::string& path, const char* key,
                    std::optional<glm::dvec3> def, double lo = -1e6, double hi = 1e6) {
        const json* v = member(obj, path, key, !def.has_value());
        if (!v)
            return def.value_or(glm::dvec3(0.0));
        if (!v->is_array() || v->size() != 3 || !(*v)[0].is_number() || !(*v)[1].is_number() ||
            !(*v)[2].is_number()) {
            fail(join(path, key),
                 fmt::format("expected an array of 3 numbers, got {}", brief_json(*v)));
            return def.value_or(glm::dvec3(0.0));
        }
        glm::dvec3 r((*v)[0].get<double>(), (*v)[1].get<double>(), (*v)[2].get<double>());
        for (int i = 0; i < 3; ++i) {
            if (!std::isfinite(r[i]) || r[i] < lo || r[i] > hi) {
                fail(join(path, key),
                     fmt::format("component {} must lie in [{}, {}], got {}", i, lo, hi, r[i]));
            }
        }
        return r;
    }

    std::string string(const json& obj, const std::string& path, const char* key,
                       std::optional<std::string> def) {
        const json* v = member(obj, path, key, !def.has_value());
        if (!v)
            return def.value_or("");
        if (!v->is_string()) {
            fail(join(path, key), fmt::format("expected a string, got {}", v->type_name()));
            return def.value_or("");
        }
        return v->get<std::string>();
    }

    bool boolean(const json& obj, const std::string& path, const char* key, bool def) {
        const json* v = member(obj, path, key, false);
        if (!v)
            return def;
        if (!v->is_boolean()) {
            fail(join(path, key), fmt::format("expected true or false, got {}", brief_json(*v)));
            return def;
        }
        return v->get<bool>();
    }

    static std::string join(const std::string& path, const std::string& key) {
        return path.empty() ? key : path + "." + key;
    }

private:
    std::string source_;
    std::optional<Error> error_;
};

Specular read_specular(Reader& r, const json& j, const std::string& path) {
    r.only(j, path,
           {"model", "colour", "exponent", "alpha_x", "alpha_y", "tangent_axis", "tangent_source"});
    Specular s;
    auto model = parse_specular_model(r.string(j, path, "model", std::nullopt));
    if (!model)
        r.fail(Reader::join(path, "model"), model.error().message);
    else
        s.model = model.value();
    s.colour = r.vec3(j, path, "colour", glm::dvec3(0.0), 0.0, 1e3);
    s.exponent = r.number(j, path, "exponent", 1.0, 1.0, 1e6);
    s.alpha_x = r.number(j, path, "alpha_x", 0.2, 1e-6, 10.0);
    s.alpha_y = r.number(j, path, "alpha_y", s.alpha_x, 1e-6, 10.0);
    s.tangent_axis = r.vec3(j, path, "tangent_axis", glm::dvec3(1, 0, 0));
    if (glm::length(s.tangent_axis) < 1e-9)
        r.fail(Reader::join(path, "tangent_axis"), "must not be zero");
    else
        s.tangent_axis = glm::normalize(s.tangent_axis);
    std::string src = r.string(j, path, "tangent_source", "axis");
    if (src == "mesh")
        s.tangent_source = Specular::TangentSource::kMesh;
    else if (src != "axis")
        r.fail(Reader::join(path, "tangent_source"),
               fmt::format("expected \"axis\" or \"mesh\", got \"{}\"", src));
    return s;
}

void read_optics(Reader& r, const json& o, Optics* out) {
    Optics& op = *out;
    r.only(o, "optics",
           {"levels", "prop_albedo", "prop_sheen", "prop_sheen_exponent", "exposure_ms", "bits",
            "noise_dn", "scene_to_signal", "effects", "compensation", "comment"});
    if (const json* l = r.member(o, "optics", "levels", false)) {
        const std::string p = "optics.levels";
        r.only(*l, p, {"projector_max", "projector_min", "hmd_max", "hmd_min", "environment"});
        DeviceLevels& d = op.levels;
        d.projector_max = r.number(*l, p, "projector_max", d.projector_max, 1e-9, 1e12);
        d.projector_min = r.number(*l, p, "projector_min", d.projector_min, 0.0, 1e12);
        d.hmd_max = r.number(*l, p, "hmd_max", d.hmd_max, 1e-9, 1e12);
        d.hmd_min = r.number(*l, p, "hmd_min", d.hmd_min, 0.0, 1e12);
        d.environment = r.number(*l, p, "environment", d.environment, 0.0, 1e12);
        if (!r.failed() && d.projector_min >= d.projector_max)
            r.fail(p + ".projector_min", "must be below projector_max");
        if (!r.failed() && d.hmd_min >= d.hmd_max)
            r.fail(p + ".hmd_min", "must be below hmd_max");
    }
    op.prop_albedo = r.vec3(o, "optics", "prop_albedo", op.prop_albedo, 0.0, 1.0);
    op.prop_sheen = r.number(o, "optics", "prop_sheen", op.prop_sheen, 0.0, 1.0);
    op.prop_sheen_exponent =
        r.number(o, "optics", "prop_sheen_exponent", op.prop_sheen_exponent, 1.0, 1e5);
    op.exposure_ms = r.number(o, "optics", "exposure_ms", op.exposure_ms, 0.0, 1e6);
    op.bits = r.integer(o, "optics", "bits", op.bits, 1, 16);
    op.noise_dn = r.number(o, "optics", "noise_dn", op.noise_dn, 0.0, 1e6);
    op.scene_to_signal = r.number(o, "optics", "scene_to_signal", op.scene_to_signal, 0.0, 1e15);
    if (const json* e = r.member(o, "optics", "effects", false)) {
        const std::string p = "optics.effects";
        r.only(*e, p,
               {"projector_falloff", "black_levels", "environment", "prop_albedo", "prop_sheen",
                "saturation", "quantisation"});
        auto& f = op.effects;
        f.projector_falloff = r.boolean(*e, p, "projector_falloff", f.projector_falloff);
        f.black_levels = r.boolean(*e, p, "black_levels", f.black_levels);
        f.environment = r.boolean(*e, p, "environment", f.environment);
        f.prop_albedo = r.boolean(*e, p, "prop_albedo", f.prop_albedo);
        f.prop_sheen = r.boolean(*e, p, "prop_sheen", f.prop_sheen);
        f.saturation = r.boolean(*e, p, "saturation", f.saturation);
        f.quantisation = r.boolean(*e, p, "quantisation", f.quantisation);
    }
    if (const json* c = r.member(o, "optics", "compensation", false)) {
        const std::string p = "optics.compensation";
        r.only(*c, p, {"falloff", "albedo", "hmd_alpha", "black_levels"});
        auto& f = op.compensation;
        f.falloff = r.boolean(*c, p, "falloff", f.falloff);
        f.albedo = r.boolean(*c, p, "albedo", f.albedo);
        f.hmd_alpha = r.boolean(*c, p, "hmd_alpha", f.hmd_alpha);
        f.black_levels = r.boolean(*c, p, "black_levels", f.black_levels);
    }
}

Pose read_pose(Reader& r, const json& j, const std::string& path) {
    r.only(j, path, {"position", "look_at", "up", "orientation_wxyz"});
    glm::dvec3 pos = r.vec3(j, path, "position", std::nullopt);
    if (j.is_object() && j.contains("orientation_wxyz")) {
        const json& q = j["orientation_wxyz"];
        if (!q.is_array() || q.size() != 4 || !q[0].is_number() || !q[1].is_number() ||
            !q[2].is_number() || !q[3].is_number()) {
            r.fail(Reader::join(path, "orientation_wxyz"),
                   "expected an array of 4 numbers (w, x, y, z)");
            return {};
        }
        glm::dquat quat(q[0].get<double>(), q[1].get<double>(), q[2].get<double>(),
                        q[3].get<double>());
        auto p = make_pose(pos, quat);
        if (!p)
            r.fail(Reader::join(path, "orientation_wxyz"), p.error().message);
        return p ? p.value() : Pose{};
    }
    glm::dvec3 target = r.vec3(j, path, "look_at", std::nullopt);
    glm::dvec3 up = r.vec3(j, path, "up", glm::dvec3(0, 1, 0));
    if (r.failed())
        return {};
    auto p = look_at(pos, target, up);
    if (!p)
        r.fail(path, p.error().message);
    return p ? p.value() : Pose{};
}

// `message` with the resolved path `real` shown as the scene wrote it, so that an error does not
// print where the asset root lies on the server.
std::string as_written(std::string message, const std::string& real, std::string_view written) {
    const std::string shown = quote_text(written);
    for (size_t at = message.find(real); !real.empty() && at != std::string::npos;
         at = message.find(real, at + shown.size()))
        message.replace(at, real.size(), shown);
    return message;
}

struct ImageSize {
    uint64_t width = 0, height = 0;  // pixels
};

// The size in a PNG's IHDR chunk, read before decoding so that a huge image is refused before
// its pixels are allocated.
Result<ImageSize> png_size(const std::filesystem::path& file) {
    unsigned char h[24] = {};
    std::ifstream in(file, std::ios::binary);
    in.read(reinterpret_cast<char*>(h), sizeof h);
    static const unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    if (!in || std::memcmp(h, kSignature, 8) != 0 || std::memcmp(h + 12, "IHDR", 4) != 0)
        return make_error(ErrorCode::kParse, "is not a PNG file");
    auto be32 = [](const unsigned char* p) {
        return uint64_t(p[0]) << 24 | uint64_t(p[1]) << 16 | uint64_t(p[2]) << 8 | p[3];
    };
    return ImageSize{be32(h + 16), be32(h + 20)};
}

// The size in an OpenEXR header's dataWindow attribute (of the first part), read before
// decoding. The header is a list of (name NUL, type NUL, int32 size, value), ended by a NUL.
Result<ImageSize> exr_size(const std::filesystem::path& file) {
    std::vector<char> h(64 * 1024);
    std::ifstream in(file, std::ios::binary);
    in.read(h.data(), std::streamsize(h.size()));
    h.resize(size_t(in.gcount()));
    auto le32 = [&](size_t at) {
        uint32_t v;
        std::memcpy(&v, h.data() + at, 4);
        return v;
    };
    if (h.size() < 8 || le32(0) != 20000630u)  // the OpenEXR magic number
        return make_error(ErrorCode::kParse, "is not an OpenEXR file");
    size_t at = 8;
    auto cstring = [&](std::string* out) {
        size_t end = at;
        while (end < h.size() && h[end] != '\0') ++end;
        if (end >= h.size())
            return false;
        out->assign(h.data() + at, end - at);
        at = end + 1;
        return true;
    };
    std::string name, type;
    while (cstring(&name) && !name.empty() && cstring(&type)) {
        if (at + 4 > h.size())
            break;
        const uint32_t size = le32(at);
        at += 4;
        if (size > h.size() - at)
            break;
        if (name == "dataWindow" && type == "box2i" && size == 16) {
            const int64_t x0 = int32_t(le32(at)), y0 = int32_t(le32(at + 4));
            const int64_t x1 = int32_t(le32(at + 8)), y1 = int32_t(le32(at + 12));
            if (x1 < x0 || y1 < y0)
                return make_error(ErrorCode::kParse, "has an empty dataWindow");
            return ImageSize{uint64_t(x1 - x0 + 1), uint64_t(y1 - y0 + 1)};
        }
        at += size;
    }
    return make_error(ErrorCode::kParse, "has no readable dataWindow in its header");
}

JsonLimits scene_json_limits() {
    JsonLimits l;
    l.max_bytes = kMaxSceneJsonBytes;
    l.max_depth = kMaxJsonDepth;
    l.max_elements = kMaxJsonElements;
    l.max_string_bytes = kMaxJsonStringBytes;
    return l;
}

uint64_t hemisphere_triangles(uint64_t segments, uint64_t rings) {
    return rings == 0 ? 0 : segments * (2 * rings - 1);  // a fan at the pole, quads below
}

// The blocks of a scene file, each read into `s` in the order the file's keys are checked; the
// first error wins (Reader).
struct SceneReader {
    Reader& r;
    const std::filesystem::path& base_dir;
    const std::filesystem::path& asset_root;
    const SceneLimits& limits;
    Scene& s;

    // Resolves a file the scene names; on failure records the error under `key` and returns
    // nothing. The message never tells a path outside the root from a missing file.
    std::optional<std::filesystem::path> asset(const std::string& key, const std::string& written) {
        auto real = resolve_asset(written, base_dir, asset_root);
        if (!real) {
            r.fail(key, real.error().message);
            return std::nullopt;
        }
        return real.value();
    }

    void hemisphere_prop(const json& p) {
        s.prop.kind = Prop::Kind::kHemisphere;
        s.prop.hemisphere.centre = r.vec3(p, "prop", "centre", s.prop.hemisphere.centre);
        s.prop.hemisphere.radius = r.number(p, "prop", "radius_m", 0.15, 1e-3, 100.0);
        s.prop.hemisphere.segments = r.integer(p, "prop", "segments", 256, 3, 8192);
        s.prop.hemisphere.rings = r.integer(p, "prop", "rings", 64, 1, 4096);
        const uint64_t triangles =
            hemisphere_triangles(s.prop.hemisphere.segments, s.prop.hemisphere.rings);
        if (!r.failed() && triangles > limits.max_triangles)
            r.fail("prop.segments",
                   fmt::format("segments {} x rings {} make {} triangles (segments x (2 rings "
                               "- 1)), more than the limit of {} (max_triangles)",
                               s.prop.hemisphere.segments, s.prop.hemisphere.rings, triangles,
                               limits.max_triangles));
    }

    void gltf_prop(const json& p) {
        s.prop.kind = Prop::Kind::kGltf;
        const std::string g = r.string(p, "prop", "gltf", std::nullopt);
        s.prop.gltf_translation = r.vec3(p, "prop", "translation", glm::dvec3(0.0));
        s.prop.gltf_scale = r.number(p, "prop", "scale", 1.0, 1e-6, 1e6);
        if (r.failed())
            return;
        auto real = asset("prop.gltf", g);
        if (!real)
            return;
        s.prop.gltf_path = real->string();
        GltfLoadInfo info;
        info.scale = s.prop.gltf_scale;
        info.translation = s.prop.gltf_translation;
        info.asset_root = asset_root.empty() ? base_dir : asset_root;
        info.max_triangles = limits.max_triangles;
        auto mesh = load_gltf_mesh(s.prop.gltf_path, info);
        if (!mesh)
            r.fail("prop.gltf", as_written(mesh.error().message, s.prop.gltf_path, g));
        else
            s.prop.gltf_mesh = std::make_shared<const Mesh>(std::move(mesh).value());
    }

    void prop(const json& p) {
        r.only(p, "prop",
               {"kind", "centre", "radius_m", "segments", "rings", "gltf", "translation", "scale"});
        std::string kind = r.string(p, "prop", "kind", std::nullopt);
        if (kind == "hemisphere")
            hemisphere_prop(p);
        else if (kind == "gltf")
            gltf_prop(p);
        else if (!r.failed())
            r.fail("prop.kind",
                   fmt::format("expected \"hemisphere\" or \"gltf\", got \"{}\"", kind));
    }

    void albedo_texture(const json& m) {
        const std::string t = r.string(m, "material", "albedo_texture", std::nullopt);
        const char* key = "material.albedo_texture";
        std::optional<std::filesystem::path> real;
        if (!r.failed())
            real = asset(key, t);
        if (!real)
            return;
        s.material.albedo_texture_path = real->string();
        auto size = png_size(*real);
        if (!size) {
            r.fail(key, fmt::format("{} {}", quote_text(t), size.error().message));
        } else if (size->width > kMaxTextureSide || size->height > kMaxTextureSide) {
            r.fail(key, fmt::format("{} is {}x{}, more than the limit of {}x{}", quote_text(t),
                                    size->width, size->height, kMaxTextureSide, kMaxTextureSide));
        } else if (auto img = read_png(*real); !img) {
            r.fail(key, as_written(img.error().message, real->string(), t));
        } else {
            s.material.albedo_texture = std::make_shared<const ImageRgba8>(std::move(img).value());
        }
    }

    void material(const json& m) {
        r.only(m, "material", {"albedo", "albedo_texture", "specular", "emission"});
        s.material.albedo = r.vec3(m, "material", "albedo", std::nullopt, 0.0, 1.0);
        if (m.is_object() && m.contains("albedo_texture"))
            albedo_texture(m);
        if (const json* sp = r.member(m, "material", "specular", false))
            s.material.specular = read_specular(r, *sp, "material.specular");
        s.material.emission = r.vec3(m, "material", "emission", glm::dvec3(0.0), 0.0, 1e6);
    }

    void specular_presets(const json& presets) {
        if (!presets.is_object()) {
            r.fail("specular_presets", "expected an object of named specular blocks");
            return;
        }
        for (auto it = presets.begin(); it != presets.end(); ++it)
            s.specular_presets[it.key()] =
                read_specular(r, it.value(), "specular_presets." + it.key());
    }

    Light light(const json& lj, const std::string& path) {
        r.only(
            lj, path,
            {"type", "colour", "intensity", "direction", "position", "edge_u", "edge_v", "name"});
        Light l;
        std::string type = r.string(lj, path, "type", std::nullopt);
        l.colour = r.vec3(lj, path, "colour", glm::dvec3(1.0), 0.0, 1e6);
        l.intensity = r.number(lj, path, "intensity", std::nullopt, 0.0, 1e12);
        if (type == "directional") {
            l.type = LightType::kDirectional;
            l.direction = r.vec3(lj, path, "direction", std::nullopt);
            if (glm::length(l.direction) < 1e-9)
                r.fail(path + ".direction", "must not be zero");
            else
                l.direction = glm::normalize(l.direction);
        } else if (type == "point") {
            l.type = LightType::kPoint;
            l.position = r.vec3(lj, path, "position", std::nullopt);
        } else if (type == "rect") {
            l.type = LightType::kRect;
            l.position = r.vec3(lj, path, "position", std::nullopt);
            l.edge_u = r.vec3(lj, path, "edge_u", std::nullopt);
            l.edge_v = r.vec3(lj, path, "edge_v", std::nullopt);
            if (!r.failed() && !(glm::length(glm::cross(l.edge_u, l.edge_v)) > 1e-8))
                r.fail(path + ".edge_u",
                       "edge_u and edge_v must span a rectangle of at least 1e-8 m^2 "
                       "(they are zero or parallel)");
        } else if (!r.failed()) {
            r.fail(
                path + ".type",
                fmt::format("expected \"directional\", \"point\" or \"rect\", got \"{}\"", type));
        }
        return l;
    }

    void lights(const json& ls) {
        if (!ls.is_array())
            r.fail("lights", "expected an array");
        else if (ls.size() > kMaxLights)
            r.fail("lights",
                   fmt::format("at most {} lights are supported, got {}", kMaxLights, ls.size()));
        else
            for (size_t i = 0; i < ls.size(); ++i)
                s.lights.push_back(light(ls[i], fmt::format("lights[{}]", i)));
        if (!r.failed())
            if (auto placed = check_point_lights(s); !placed.ok())
                r.fail("lights", placed.error().message);
    }

    // One projector at key path `p` ("projector", or "projectors[i]" where the name is required).
    Projector projector(const json& pj, const std::string& p, bool name_required) {
        Projector out;
        r.only(pj, p,
               {"name", "width", "height", "fx", "fy", "cx", "cy", "pose", "white_level",
                "black_level", "comment"});
        Intrinsics& k = out.intrinsics;
        out.name = r.string(pj, p, "name",
                            name_required ? std::nullopt : std::optional<std::string>("projector"));
        if (!r.failed() && out.name.empty())
            r.fail(Reader::join(p, "name"), "must not be empty");
        k.width = r.integer(pj, p, "width", std::nullopt, 1, kMaxImageSide);
        k.height = r.integer(pj, p, "height", std::nullopt, 1, kMaxImageSide);
        const uint64_t pixels = uint64_t(k.width) * k.height;
        if (!r.failed() && pixels > limits.max_projector_pixels)
            r.fail(Reader::join(p, "width"),
                   fmt::format("width {} x height {} = {} pixels, more than the limit of {} "
                               "(max_projector_pixels)",
                               k.width, k.height, pixels, limits.max_projector_pixels));
        k.fx = r.number(pj, p, "fx", std::nullopt, 1e-3, 1e7);
        k.fy = r.number(pj, p, "fy", k.fx, 1e-3, 1e7);
        k.cx = r.number(pj, p, "cx", 0.5 * (k.width - 1.0), -1e5, 1e5);
        k.cy = r.number(pj, p, "cy", 0.5 * (k.height - 1.0), -1e5, 1e5);
        if (const json* pose = r.member(pj, p, "pose", true))
            out.pose = read_pose(r, *pose, Reader::join(p, "pose"));
        if (pj.is_object() && pj.contains("white_level"))
            out.white_level = r.number(pj, p, "white_level", std::nullopt, 1e-9, 1e12);
        if (pj.is_object() && pj.contains("black_level"))
            out.black_level = r.number(pj, p, "black_level", std::nullopt, 0.0, 1e12);
        return out;
    }

    void projector_list(const json& list) {
        if (!list.is_array()) {
            r.fail("projectors", fmt::format("expected an array, got {}", list.type_name()));
            return;
        }
        if (list.empty()) {
            r.fail("projectors", "expected at least one projector, got an empty list");
            return;
        }
        if (list.size() > kMaxProjectors) {
            r.fail("projectors", fmt::format("at most {} projectors are supported, got {}",
                                             kMaxProjectors, list.size()));
            return;
        }
        std::set<std::string> names;
        for (size_t i = 0; i < list.size() && !r.failed(); ++i) {
            const std::string p = fmt::format("projectors[{}]", i);
            Projector pr = projector(list[i], p, true);
            if (r.failed())
                return;
            if (!names.insert(pr.name).second) {
                r.fail(Reader::join(p, "name"), fmt::format("'{}' names an earlier projector too: "
                                                            "projector names must be unique",
                                                            pr.name));
                return;
            }
            if (i == 0)
                s.projector = std::move(pr);
            else
                s.more_projectors.push_back(std::move(pr));
        }
    }

    // Each projector's own levels against the scene's (set once both are read).
    void check_projector_levels() {
        const auto all = s.projectors();
        for (size_t i = 0; i < all.size() && !r.failed(); ++i) {
            const double hi = all[i].white_level.value_or(s.optics.levels.projector_max);
            const double lo = all[i].black_level.value_or(s.optics.levels.projector_min);
            if (lo >= hi)
                r.fail(s.more_projectors.empty() ? std::string("projector")
                                                 : fmt::format("projectors[{}]", i),
                       fmt::format("black level {} must be below the white level {}", lo, hi));
        }
    }

    // A viewer's field of view: from its intrinsics, its diagonal, or its two angles.
    void viewer_fov(const json& vj, const std::string& path, ViewerProfile& v) {
        if (vj.is_object() && vj.contains("fx")) {
            Intrinsics& k = v.intrinsics;
            v.has_intrinsics = true;
            k.width = v.eye_width;
            k.height = v.eye_height;
            k.fx = r.number(vj, path, "fx", std::nullopt, 1e-3, 1e7);
            k.fy = r.number(vj, path, "fy", k.fx, 1e-3, 1e7);
            k.cx = r.number(vj, path, "cx", 0.5 * (k.width - 1.0), -1e5, 1e5);
            k.cy = r.number(vj, path, "cy", 0.5 * (k.height - 1.0), -1e5, 1e5);
            v.fov_x_rad = 2 * std::atan(0.5 * k.width / k.fx);
            v.fov_y_rad = 2 * std::atan(0.5 * k.height / k.fy);
        } else if (vj.is_object() && vj.contains("fov_diagonal_deg")) {
            double d = r.number(vj, path, "fov_diagonal_deg", std::nullopt, 0.1, 179.0);
            fov_from_diagonal(glm::radians(d), v.eye_width, v.eye_height, &v.fov_x_rad,
                              &v.fov_y_rad);
        } else {
            v.fov_x_rad = glm::radians(r.number(vj, path, "fov_x_deg", std::nullopt, 0.1, 179.0));
            v.fov_y_rad = glm::radians(r.number(vj, path, "fov_y_deg", std::nullopt, 0.1, 179.0));
        }
    }

    ViewerProfile viewer(const json& vj, const std::string& path) {
        r.only(vj, path,
               {"name", "eye_width", "eye_height", "fov_x_deg", "fov_y_deg", "fov_diagonal_deg",
                "fx", "fy", "cx", "cy", "ipd_m", "alpha", "comment"});
        ViewerProfile v;
        v.name = r.string(vj, path, "name", std::nullopt);
        v.eye_width = r.integer(vj, path, "eye_width", std::nullopt, 1, kMaxImageSide);
        v.eye_height = r.integer(vj, path, "eye_height", std::nullopt, 1, kMaxImageSide);
        viewer_fov(vj, path, v);
        v.ipd_m = r.number(vj, path, "ipd_m", 0.063, 0.0, 0.2);
        v.alpha = r.number(vj, path, "alpha", 1.0, 0.0, 1.0);
        if (!r.failed() && s.find_viewer(v.name))
            r.fail(path + ".name", fmt::format("duplicate viewer name '{}'", v.name));
        return v;
    }

    void viewers(const json& vs) {
        if (!vs.is_array() || vs.empty()) {
            r.fail("viewers", "expected a non-empty array of headset profiles");
            return;
        }
        for (size_t i = 0; i < vs.size(); ++i)
            s.viewers.push_back(viewer(vs[i], fmt::format("viewers[{}]", i)));
    }

    void viewing_angles(const json& a) {
        s.viewing.angles_deg.clear();
        if (!a.is_array() || a.empty()) {
            r.fail("viewing.angles_deg", "expected a non-empty array of numbers");
            return;
        }
        for (size_t i = 0; i < a.size(); ++i) {
            const json& x = a[i];
            const std::string at = fmt::format("viewing.angles_deg[{}]", i);
            if (!x.is_number()) {
                r.fail(at, fmt::format("expected a number, got {}", x.type_name()));
                return;
            }
            const double deg = x.get<double>();
            if (!std::isfinite(deg) || std::abs(deg) > kMaxViewAngleDeg) {
                r.fail(at, fmt::format("expected a number in [{}, {}], got {}", -kMaxViewAngleDeg,
                                       kMaxViewAngleDeg, deg));
                return;
            }
            s.viewing.angles_deg.push_back(deg);
        }
    }

    void viewing(const json& vw) {
        r.only(vw, "viewing",
               {"target", "distance_m", "angles_deg", "heights_m", "default_height"});
        s.viewing.target = r.vec3(vw, "viewing", "target", s.viewing.target);
        s.viewing.distance_m =
            r.number(vw, "viewing", "distance_m", s.viewing.distance_m, 1e-3, 1e4);
        if (const json* a = r.member(vw, "viewing", "angles_deg", false))
            viewing_angles(*a);
        if (const json* h = r.member(vw, "viewing", "heights_m", false)) {
            s.viewing.heights_m.clear();
            if (!h->is_object() || h->empty())
                r.fail("viewing.heights_m", "expected an object of name: height");
            else
                for (auto it = h->begin(); it != h->end(); ++it)
                    s.viewing.heights_m[it.key()] =
                        r.number(*h, "viewing.heights_m", it.key().c_str(), std::nullopt,
                                 -kMaxViewHeightM, kMaxViewHeightM);
        }
        s.viewing.default_height =
            r.string(vw, "viewing", "default_height", s.viewing.default_height);
        if (!r.failed() && !s.viewing.heights_m.count(s.viewing.default_height))
            r.fail("viewing.default_height",
                   fmt::format("'{}' is not a key of viewing.heights_m", s.viewing.default_height));
    }

    // One image of a captured material: an EXR inside the asset root, within the size limits,
    // every value finite. Null, with the error recorded, otherwise.
    std::shared_ptr<const ImageRgba32f> captured_image(const json& c, const char* key,
                                                       std::string* path) {
        const char* p = "captured_material";
        const std::string f = r.string(c, p, key, std::nullopt);
        const std::string where = Reader::join(p, key);
        if (r.failed())
            return nullptr;
        auto real = asset(where, f);
        if (!real)
            return nullptr;
        *path = real->string();
        auto size = exr_size(*real);
        if (!size) {
            r.fail(where, fmt::format("{} {}", quote_text(f), size.error().message));
            return nullptr;
        }
        if (size->width > kMaxImageSide || size->height > kMaxImageSide ||
            size->width * size->height > kMaxCapturedImagePixels) {
            r.fail(where, fmt::format("{} is {}x{}, more than the limit of {} pixels a side "
                                      "and {} pixels",
                                      quote_text(f), size->width, size->height, kMaxImageSide,
                                      kMaxCapturedImagePixels));
            return nullptr;
        }
        auto img = read_exr(*real);
        if (!img) {
            r.fail(where, as_written(img.error().message, *path, f));
            return nullptr;
        }
        for (float v : img->pixels)
            if (!std::isfinite(v)) {
                r.fail(where, quote_text(f) + " has a non-finite value");
                return nullptr;
            }
        return std::make_shared<const ImageRgba32f>(std::move(img).value());
    }

    void captured_material(const json& c) {
        const char* p = "captured_material";
        r.only(c, p,
               {"projector_image", "viewer_image", "capture_head", "position_tolerance_m",
                "angle_tolerance_deg", "comment"});
        CapturedMaterial m;
        m.projector_image = captured_image(c, "projector_image", &m.projector_image_path);
        m.viewer_image = captured_image(c, "viewer_image", &m.viewer_image_path);
        if (const json* h = r.member(c, p, "capture_head", true))
            m.capture_head = read_pose(r, *h, "captured_material.capture_head");
        m.position_tolerance_m =
            r.number(c, p, "position_tolerance_m", m.position_tolerance_m, 0.0, 100.0);
        m.angle_tolerance_deg =
            r.number(c, p, "angle_tolerance_deg", m.angle_tolerance_deg, 0.0, 180.0);
        if (m.projector_image && !r.failed() &&
            (m.projector_image->width != s.projector.intrinsics.width ||
             m.projector_image->height != s.projector.intrinsics.height))
            r.fail("captured_material.projector_image",
                   fmt::format("{} is {}x{}, the projector is {}x{}",
                               quote_text(r.string(c, p, "projector_image", std::nullopt)),
                               m.projector_image->width, m.projector_image->height,
                               s.projector.intrinsics.width, s.projector.intrinsics.height));
        s.captured_material = std::move(m);
    }
};

Result<Scene> parse_scene_tree(const json& root, const std::string& source,
                               const std::filesystem::path& base_dir,
                               const std::filesystem::path& asset_root, const SceneLimits& limits) {
    Reader r(source);
    Scene s;
    if (!root.is_object())
        return make_error(ErrorCode::kParse,
                          fmt::format("{}: expected a JSON object at the top", source));
    r.only(
        root, "",
        {"schema_version", "name", "prop", "material", "specular_presets", "lights", "projector",
         "projectors", "viewers", "viewing", "effects", "optics", "captured_material", "comment"});
    s.schema_version = int(r.integer(root, "", "schema_version", std::nullopt, 0, 1000));
    if (!r.failed() && s.schema_version != kSchemaVersion) {
        r.fail("schema_version", fmt::format("this build reads schema_version {}, the file has {}",
                                             kSchemaVersion, s.schema_version));
    }
    s.name = r.string(root, "", "name", "unnamed");
    SceneReader read{r, base_dir, asset_root, limits, s};
    if (const json* p = r.member(root, "", "prop", true))
        read.prop(*p);
    if (const json* m = r.member(root, "", "material", true))
        read.material(*m);
    if (const json* presets = r.member(root, "", "specular_presets", false))
        read.specular_presets(*presets);
    if (const json* ls = r.member(root, "", "lights", true))
        read.lights(*ls);
    if (root.contains("projector") && root.contains("projectors"))
        r.fail("projectors", "give either `projector` (one) or `projectors` (a list), not both");
    else if (const json* list = r.member(root, "", "projectors", false))
        read.projector_list(*list);
    else if (const json* pj = r.member(root, "", "projector", false))
        s.projector = read.projector(*pj, "projector", false);
    else
        r.fail("projectors", "missing required key (`projectors`, a list, or `projector`)");
    if (const json* vs = r.member(root, "", "viewers", true))
        read.viewers(*vs);
    if (const json* vw = r.member(root, "", "viewing", false))
        read.viewing(*vw);
    if (const json* e = r.member(root, "", "effects", false)) {
        r.only(*e, "effects", {"point_light_falloff", "headset_fill"});
        s.effects.point_light_falloff = r.boolean(*e, "effects", "point_light_falloff", true);
        s.effects.headset_fill = r.boolean(*e, "effects", "headset_fill", true);
    }
    if (const json* o = r.member(root, "", "optics", false))
        read_optics(r, *o, &s.optics);
    if (const json* c = r.member(root, "", "captured_material", false))
        read.captured_material(*c);
    if (!r.failed())
        read.check_projector_levels();
    if (!r.failed() && s.captured_material && !s.more_projectors.empty())
        r.fail("captured_material",
               "a captured material is made for one projector; this scene "
               "has " +
                   std::to_string(s.projector_count()));
    if (r.failed())
        return r.error();
    return s;
}

}  // namespace

Result<Scene> parse_scene(std::string_view text, const std::string& source,
                          const std::filesystem::path& base_dir,
                          const std::filesystem::path& asset_root, const SceneLimits& limits) {
    HS_ASSIGN_OR_RETURN(json root, parse_json_limited(text, source, scene_json_limits()));
    // The readers check every type before reading it; this catch keeps a missed check (or an
    // allocation failure) an error of this scene rather than of the process.
    try {
        return parse_scene_tree(root, source, base_dir, asset_root, limits);
    } catch (const std::exception& e) {
        return make_error(ErrorCode::kParse,
                          fmt::format("{}: could not read the scene: {}", source, e.what()));
    }
}

bool is_scene_document(std::string_view text) {
    auto root = parse_json_limited(text, "scene", scene_json_limits());
    if (!root || !root->is_object())
        return false;
    const auto v = root->find("schema_version");
    return v != root->end() && v->is_number_integer();
}

Result<Scene> load_scene_file(const std::filesystem::path& path,
                              const std::filesystem::path& asset_root, const SceneLimits& limits) {
    std::error_code ec;
    const auto size = std::filesystem::file_size(path, ec);
    if (!ec && size > kMaxSceneJsonBytes)
        return make_error(ErrorCode::kParse,
                          fmt::format("{}: the file is {} bytes, more than the limit of {} bytes",
                                      path.string(), size, kMaxSceneJsonBytes));
    std::ifstream in(path, std::ios::binary);
    if (!in)
        return make_error(ErrorCode::kNotFound,
                          fmt::format("{}: cannot open scene file", path.string()));
    std::string text;
    try {
        std::stringstream ss;
        ss << in.rdbuf();
        text = std::move(ss).str();
    } catch (const std::exception& e) {
        return make_error(ErrorCode::kIo,
                          fmt::format("{}: could not read the file: {}", path.string(), e.what()));
    }
    const std::filesystem::path dir =
        path.parent_path().empty() ? std::filesystem::path(".") : path.parent_path();
    return parse_scene(text, path.string(), dir, asset_root.empty() ? dir : asset_root, limits);
}

uint64_t prop_triangle_count(const Prop& prop) {
    if (prop.kind == Prop::Kind::kHemisphere)
        return hemisphere_triangles(prop.hemisphere.segments, prop.hemisphere.rings);
    return prop.gltf_mesh ? prop.gltf_mesh->indices.size() / 3 : 0;
}

Result<void> check_scene_limits(const Scene& scene, const SceneLimits& limits) {
    const uint64_t triangles = prop_triangle_count(scene.prop);
    if (triangles > limits.max_triangles) {
        const std::string what =
            scene.prop.kind == Prop::Kind::kHemisphere
                ? fmt::format("prop.segments x prop.rings ({} x {})",
                              scene.prop.hemisphere.segments, scene.prop.hemisphere.rings)
                : std::string("prop.gltf");
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("scene '{}': {} makes {} triangles, more than the limit of "
                                      "{} (max_triangles)",
                                      scene.name, what, triangles, limits.max_triangles));
    }
    for (const Projector& p : scene.projectors()) {
        const Intrinsics& k = p.intrinsics;
        const uint64_t pixels = uint64_t(k.width) * k.height;
        if (pixels > limits.max_projector_pixels)
            return make_error(
                ErrorCode::kInvalidArgument,
                fmt::format("scene '{}': projector {}width {} x height {} = {} pixels, "
                            "more than the limit of {} (max_projector_pixels)",
                            scene.name, scene.more_projectors.empty() ? "" : "'" + p.name + "' ",
                            k.width, k.height, pixels, limits.max_projector_pixels));
    }
    // Several projectors: their pixels together, since the blend holds and weighs every one
    // of them on the render thread at each scene version.
    uint64_t total = 0;
    for (const Projector& p : scene.projectors())
        total += uint64_t(p.intrinsics.width) * p.intrinsics.height;
    if (scene.projectors().size() > 1 && total > limits.max_projector_pixels)
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("scene '{}': the {} projectors have {} pixels together, more "
                        "than the limit of {} (max_projector_pixels, which bounds "
                        "the blend of several projectors too)",
                        scene.name, scene.projectors().size(), total, limits.max_projector_pixels));
    return {};
}

}  // namespace hs::scene
