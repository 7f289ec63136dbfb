#include "bench/accuracy.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>

#include <fmt/format.h>
#include <glm/geometric.hpp>

#include "codec/layer_codec.hpp"
#include "optics/colour.hpp"
#include "plot/plot.hpp"
#include "render/renderer.hpp"
#include "scene/camera.hpp"
#include "scene/mesh.hpp"
#include "shading/compare.hpp"
#include "shading/reference.hpp"

namespace hs::bench {

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// The same fields of view at `scale` times the resolution (pixel edges kept in place).
scene::Intrinsics scaled_intrinsics(const scene::Intrinsics& k, double scale) {
    scene::Intrinsics o;
    o.width = std::max<uint32_t>(1, uint32_t(std::lround(k.width * scale)));
    o.height = std::max<uint32_t>(1, uint32_t(std::lround(k.height * scale)));
    const double sx = double(o.width) / k.width, sy = double(o.height) / k.height;
    o.fx = k.fx * sx, o.fy = k.fy * sy;
    o.cx = (k.cx + 0.5) * sx - 0.5, o.cy = (k.cy + 0.5) * sy - 0.5;
    return o;
}

// n x n pixels averaged into one (alpha becomes the coverage).
ImageRgba32f box_down(const ImageRgba32f& img, uint32_t n) {
    ImageRgba32f out = ImageRgba32f::zeros(img.width / n, img.height / n);
    const float w = 1.0f / float(n * n);
    for (uint32_t y = 0; y < out.height; ++y)
        for (uint32_t x = 0; x < out.width; ++x) {
            glm::vec4 sum(0.0f);
            for (uint32_t j = 0; j < n; ++j)
                for (uint32_t i = 0; i < n; ++i) sum += img.at(x * n + i, y * n + j);
            out.set(x, y, sum * w);
        }
    return out;
}

// `img` rendered through `src` resampled bilinearly to `dst` (same fields of view).
ImageRgba32f bilinear_to(const ImageRgba32f& img, const scene::Intrinsics& src,
                         const scene::Intrinsics& dst) {
    ImageRgba32f out = ImageRgba32f::zeros(dst.width, dst.height);
    for (uint32_t y = 0; y < dst.height; ++y)
        for (uint32_t x = 0; x < dst.width; ++x) {
            const double u = (x - dst.cx) * src.fx / dst.fx + src.cx;
            const double v = (y - dst.cy) * src.fy / dst.fy + src.cy;
            double px[4];
            if (sample_bilinear(img, u, v, px))
                out.set(x, y, glm::vec4(float(px[0]), float(px[1]), float(px[2]), float(px[3])));
        }
    return out;
}

struct Errors {
    double rmse = 0, mean_de00 = 0;
};

// RMSE over pixels either covers; mean CIEDE2000 where the reference shows in an RGBA8 layer.
Errors errors_of(const ImageRgba32f& img, const ImageRgba32f& ref) {
    Errors e;
    const auto st = shading::compare_images(img, ref, {}, 0.0);
    e.rmse = st.non_finite ? INFINITY : st.rmse;
    double sum = 0;
    size_t n = 0;
    const float visible = 1.0f / 255.0f;
    for (size_t i = 0; i < size_t(ref.width) * ref.height; ++i) {
        const float* q = &ref.pixels[i * 4];
        if (!(q[3] > 0.5f) || std::max({q[0], q[1], q[2]}) < visible)
            continue;
        const float* p = &img.pixels[i * 4];
        const auto a =
            optics::lab_from_linear_srgb(glm::dvec3(p[0], p[1], p[2]) / double(codec::kLayerWhite));
        const auto b =
            optics::lab_from_linear_srgb(glm::dvec3(q[0], q[1], q[2]) / double(codec::kLayerWhite));
        sum += optics::delta_e_2000(a, b);
        ++n;
    }
    e.mean_de00 = n ? sum / n : 0.0;
    return e;
}

struct LayerEncoding {
    std::string name;
    protocol::PixelFormat format;
    protocol::Encoding encoding;
    protocol::TileCodec codec;
    int quality = protocol::kDefaultLayerQuality;  // lossy tiles' JPEG quality (codec 3)
};
const LayerEncoding kDefaultEncoding{"f16 tiles+lz4", protocol::PixelFormat::kRgba16f,
                                     protocol::Encoding::kSparseTiles,
                                     codec::default_tile_codec(protocol::PixelFormat::kRgba16f)};

struct Encoded {
    std::vector<uint8_t> data;
    double ms = 0;  // median
};

Encoded encode(const ImageRgba32f& img, const LayerEncoding& e, int repeats) {
    Encoded out;
    std::vector<double> t;
    for (int r = 0; r < std::max(1, repeats); ++r) {
        const auto t0 = Clock::now();
        auto px = codec::encode_pixels(img, e.format);
        out.data = codec::encode_layer(px, img.width, img.height, e.format, e.encoding, e.codec,
                                       e.quality);
        t.push_back(ms_since(t0));
    }
    out.ms = median(t);
    return out;
}

// What a client shows from the encoded layer (alpha: the coverage of `img`, for the error).
ImageRgba32f decode(const Encoded& enc, const ImageRgba32f& img, const LayerEncoding& e) {
    std::vector<uint8_t> px = enc.data;
    if (e.encoding != protocol::Encoding::kRaw) {
        const uint32_t bpp = e.format == protocol::PixelFormat::kRgba8 ? 4 : 8;
        auto d = protocol::decode_tiles(enc.data, img.width, img.height, bpp);
        if (!std::holds_alternative<std::vector<uint8_t>>(d))
            return ImageRgba32f::zeros(img.width, img.height);
        px = std::get<std::vector<uint8_t>>(d);
    }
    ImageRgba32f out = codec::decode_pixels(px, img.width, img.height, e.format);
    for (size_t i = 0; i < size_t(img.width) * img.height && !out.pixels.empty(); ++i)
        out.pixels[i * 4 + 3] = img.pixels[i * 4 + 3];
    return out;
}

struct Measured {
    ImageRgba32f image;  // of the first (untimed) run, as the headset shows it
    ImageRgba32f sent;   // the layer as sent, where it differs (a reduced render scale)
    double ms = 0;       // median of the timed runs
};

// One warm-up run (pipelines built, targets allocated) kept for the errors, then `repeats`
// timed runs.
Result<Measured> measure(const std::function<Result<ImageRgba32f>()>& f, int repeats) {
    Measured m;
    HS_ASSIGN_OR_RETURN(m.image, f());
    std::vector<double> t;
    for (int r = 0; r < repeats; ++r) {
        const auto t0 = Clock::now();
        HS_ASSIGN_OR_RETURN(auto img, f());
        t.push_back(ms_since(t0));
    }
    m.ms = median(t);
    return m;
}

// The point lights of the paper's approximation of a rect light: an n x n grid of midpoints,
// each with 1/n^2 of the panel's intensity towards `target` (a point light is isotropic).
std::vector<scene::Light> points_for(const scene::Light& rect, int n, glm::dvec3 target) {
    const glm::dvec3 ne = glm::normalize(glm::cross(rect.edge_u, rect.edge_v));
    std::vector<scene::Light> out;
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            scene::Light l;
            l.type = scene::LightType::kPoint;
            l.colour = rect.colour;
            l.position = rect.position + ((i + 0.5) / n - 0.5) * rect.edge_u +
                         ((j + 0.5) / n - 0.5) * rect.edge_v;
            const double cos_e = std::max(glm::dot(ne, glm::normalize(target - l.position)), 0.0);
            l.intensity = rect.intensity * cos_e / (n * n);
            out.push_back(l);
        }
    return out;
}

class Sweep {
public:
    Sweep(gpu::Device& device, const scene::Scene& s, const AccuracyOptions& o)
        : device_(device), s_(s), o_(o), repeats_(o.quick ? 2 : std::max(1, o.repeats)) {}

    Result<AccuracyReport> run();

private:
    void say(const std::string& line) const {
        if (o_.progress)
            o_.progress(line);
    }
    Result<std::unique_ptr<render::Renderer>> renderer(
        const scene::Scene& s, gpu::ColorFormat format,
        uint32_t area_samples = render::kDefaultAreaLightSamples, bool level_of_detail = true) {
        render::RendererCreateInfo info;
        info.format = format;
        info.area_light_samples = area_samples;
        info.level_of_detail = level_of_detail;
        return render::Renderer::create(device_, s, info);
    }
    // The layer at `k_` rendered at `scale` times its resolution, timed. Integer scales > 1 are
    // supersampling, box-filtered on the server (timed); other scales send the small layer and
    // the headset resamples it bilinearly (untimed: the client's GPU does it).
    Result<Measured> render_layer(render::Renderer& r, double scale) {
        const scene::Intrinsics kr = scaled_intrinsics(k_, scale);
        const auto n = uint32_t(std::lround(scale));
        const bool box = scale > 1 && std::abs(scale - n) < 1e-9;
        HS_ASSIGN_OR_RETURN(Measured m, measure(
                                            [&]() -> Result<ImageRgba32f> {
                                                HS_ASSIGN_OR_RETURN(auto out,
                                                                    r.render_eye(spec_, kr, eye_));
                                                if (box)
                                                    return box_down(out.image, n);
                                                return std::move(out.image);
                                            },
                                            repeats_));
        if (!box && scale != 1.0) {
            m.sent = std::move(m.image);
            m.image = bilinear_to(m.sent, kr, k_);
        }
        return m;
    }
    // A row from a measured layer: errors against `ref`, cost with the default encoding.
    AccuracyRow row(const std::string& knob, const std::string& setting, const char* reference,
                    bool is_default, const Measured& m, const ImageRgba32f& ref) {
        AccuracyRow r;
        r.knob = knob, r.setting = setting, r.reference = reference, r.is_default = is_default;
        const Errors e = errors_of(m.image, ref);
        r.rmse = e.rmse, r.mean_de00 = e.mean_de00, r.render_ms = m.ms;
        const Encoded enc =
            encode(m.sent.pixels.empty() ? m.image : m.sent, kDefaultEncoding, repeats_);
        r.encode_ms = enc.ms, r.bytes = double(enc.data.size());
        say(fmt::format("  {:<18} {:<18} rmse {:.3e}  dE00 {:.3f}  render {:.1f} ms", knob, setting,
                        r.rmse, r.mean_de00, r.render_ms));
        return r;
    }

    Result<void> tessellation(std::vector<AccuracyRow>& rows);
    Result<void> render_scale(std::vector<AccuracyRow>& rows);
    Result<void> samples_per_pixel(std::vector<AccuracyRow>& rows);
    Result<void> lights(std::vector<AccuracyRow>& rows);
    Result<void> formats_and_encodings(std::vector<AccuracyRow>& rows);

    gpu::Device& device_;
    scene::Scene s_;
    AccuracyOptions o_;
    int repeats_;
    scene::Specular spec_;
    scene::Intrinsics k_;
    scene::Pose eye_;
    ImageRgba32f ref_centre_;
};

Result<void> Sweep::tessellation(std::vector<AccuracyRow>& rows) {
    const scene::Hemisphere def{};
    std::vector<std::pair<uint32_t, uint32_t>> grid = {{16, 4},   {32, 8},   {64, 16},
                                                       {128, 32}, {256, 64}, {512, 128}};
    if (o_.quick)
        grid.pop_back();
    // Fixed tessellations (level of detail off), then the server's default: the level of
    // detail chosen for this view under the scene's own segments x rings.
    for (auto [seg, rings] : grid) {
        scene::Scene s = s_;
        s.prop.hemisphere.segments = seg, s.prop.hemisphere.rings = rings;
        HS_ASSIGN_OR_RETURN(auto r, renderer(s, gpu::ColorFormat::kRgba16Float,
                                             render::kDefaultAreaLightSamples, false));
        HS_ASSIGN_OR_RETURN(auto m, render_layer(*r, 1.0));
        const bool is_def = seg == def.segments && rings == def.rings;
        AccuracyRow row_ =
            row("tessellation", fmt::format("{}x{}", seg, rings), "centre", is_def, m, ref_centre_);
        row_.geometric_error_mm = hemisphere_geometric_error_mm(s.prop.hemisphere);
        rows.push_back(row_);
    }
    // The level of detail: the scene's own tessellation for every view, against the coarsest
    // level whose shell stays within half a pixel of this view (the server's default).
    for (bool lod : {false, true}) {
        HS_ASSIGN_OR_RETURN(auto r, renderer(s_, gpu::ColorFormat::kRgba16Float,
                                             render::kDefaultAreaLightSamples, lod));
        HS_ASSIGN_OR_RETURN(auto m, render_layer(*r, 1.0));
        const auto& level = r->levels()[r->level_for(k_, eye_)];
        AccuracyRow lr =
            row("level-of-detail",
                fmt::format("{} {}x{}", lod ? "per-view" : "fixed", level.segments, level.rings),
                "centre", lod, m, ref_centre_);
        lr.geometric_error_mm = level.surface_error_m * 1000.0;
        rows.push_back(lr);
    }
    return {};
}

Result<void> Sweep::render_scale(std::vector<AccuracyRow>& rows) {
    HS_ASSIGN_OR_RETURN(auto r, renderer(s_, gpu::ColorFormat::kRgba16Float));
    for (double scale : {0.25, 0.5, 0.75, 1.0}) {
        HS_ASSIGN_OR_RETURN(auto m, render_layer(*r, scale));
        rows.push_back(row("render-scale", fmt::format("{:g}", scale), "centre", scale == 1.0, m,
                           ref_centre_));
    }
    return {};
}

Result<void> Sweep::samples_per_pixel(std::vector<AccuracyRow>& rows) {
    say("reference: the pixel-area integral, 8 x 8 rays per pixel");
    shading::ReferenceOptions ro;
    ro.pixel_grid = 8;
    HS_ASSIGN_OR_RETURN(auto ref_box, shading::reference_viewer(s_, spec_, k_, eye_, nullptr, ro));
    HS_ASSIGN_OR_RETURN(auto r, renderer(s_, gpu::ColorFormat::kRgba16Float));
    for (uint32_t n = 1; n <= (o_.quick ? 3u : 4u); ++n) {
        HS_ASSIGN_OR_RETURN(auto m, render_layer(*r, double(n)));
        rows.push_back(
            row("samples-per-pixel", fmt::format("{} spp", n * n), "box", n == 1, m, ref_box));
    }
    return {};
}

Result<void> Sweep::lights(std::vector<AccuracyRow>& rows) {
    // The room's point lights become 0.4 m softboxes facing the prop: the integral of eq. (1).
    scene::Scene area = s_;
    const glm::dvec3 target = s_.prop.hemisphere.centre;
    for (auto& l : area.lights)
        if (l.type == scene::LightType::kPoint) {
            HS_ASSIGN_OR_RETURN(scene::Light rect, scene::rect_light_facing(l.position, target, 0.4,
                                                                            0.4, l.intensity));
            rect.colour = l.colour;
            l = rect;
        }
    const auto panels = size_t(std::count_if(area.lights.begin(), area.lights.end(), [](auto& l) {
        return l.type == scene::LightType::kRect;
    }));
    if (panels == 0) {
        say("lights: the scene has no point light to widen into a softbox; knob left out");
        return {};
    }
    say("reference: the area lights' integral, 32 x 32 cells per panel");
    HS_ASSIGN_OR_RETURN(auto ref_area, shading::reference_viewer(area, spec_, k_, eye_));
    for (int n : o_.quick ? std::vector<int>{1, 2, 3} : std::vector<int>{1, 2, 3, 4, 5}) {
        if (area.lights.size() + panels * (n * n - 1) > scene::kMaxLights) {
            say(fmt::format("lights: {} points per panel exceed {} lights; left out", n * n,
                            scene::kMaxLights));
            continue;
        }
        scene::Scene pts = area;
        pts.lights.clear();
        for (const auto& l : area.lights) {
            if (l.type != scene::LightType::kRect) {
                pts.lights.push_back(l);
                continue;
            }
            for (const auto& p : points_for(l, n, target)) pts.lights.push_back(p);
        }
        HS_ASSIGN_OR_RETURN(auto r, renderer(pts, gpu::ColorFormat::kRgba16Float));
        HS_ASSIGN_OR_RETURN(auto m, render_layer(*r, 1.0));
        rows.push_back(
            row("lights", fmt::format("points N={}", n * n), "area", false, m, ref_area));
    }
    for (uint32_t k :
         o_.quick ? std::vector<uint32_t>{1, 4, 16} : std::vector<uint32_t>{1, 4, 16, 64, 256}) {
        HS_ASSIGN_OR_RETURN(auto r, renderer(area, gpu::ColorFormat::kRgba16Float, k));
        HS_ASSIGN_OR_RETURN(auto m, render_layer(*r, 1.0));
        rows.push_back(row("lights", fmt::format("area K={}", k), "area",
                           k == render::kDefaultAreaLightSamples, m, ref_area));
    }
    return {};
}

Result<void> Sweep::formats_and_encodings(std::vector<AccuracyRow>& rows) {
    struct Format {
        const char* name;
        gpu::ColorFormat f;
    };
    std::map<std::string, Measured> by_format;
    for (Format f : {Format{"rgba8", gpu::ColorFormat::kRgba8Unorm},
                     Format{"rgba16f", gpu::ColorFormat::kRgba16Float},
                     Format{"rgba32f", gpu::ColorFormat::kRgba32Float}}) {
        HS_ASSIGN_OR_RETURN(auto r, renderer(s_, f.f));
        HS_ASSIGN_OR_RETURN(auto m, render_layer(*r, 1.0));
        rows.push_back(
            row("format", f.name, "centre", f.f == gpu::ColorFormat::kRgba16Float, m, ref_centre_));
        by_format[f.name] = std::move(m);
    }
    // Layer encodings: what a client decodes, against the reference.
    const std::vector<LayerEncoding> encodings = {
        {"f16 raw", protocol::PixelFormat::kRgba16f, protocol::Encoding::kRaw,
         protocol::TileCodec::kNone},
        {"f16 tiles", protocol::PixelFormat::kRgba16f, protocol::Encoding::kSparseTiles,
         protocol::TileCodec::kNone},
        kDefaultEncoding,
        {"f16 tiles+zstd", protocol::PixelFormat::kRgba16f, protocol::Encoding::kSparseTiles,
         protocol::TileCodec::kZstd},
        {"srgb8 tiles+zstd", protocol::PixelFormat::kRgba8, protocol::Encoding::kSparseTiles,
         protocol::TileCodec::kZstd},
        // Lossy tiles (`hysar serve --layer-quality`): the quality knob, default 92.
        {"srgb8 lossy q70", protocol::PixelFormat::kRgba8, protocol::Encoding::kLossyTiles,
         protocol::TileCodec::kJpeg, 70},
        {"srgb8 lossy q92", protocol::PixelFormat::kRgba8, protocol::Encoding::kLossyTiles,
         protocol::TileCodec::kJpeg, 92},
        {"srgb8 lossy q95", protocol::PixelFormat::kRgba8, protocol::Encoding::kLossyTiles,
         protocol::TileCodec::kJpeg, 95}};
    auto encoded_row = [&](const std::string& knob, const std::string& setting, bool is_default,
                           const Measured& m, const LayerEncoding& e) {
        AccuracyRow r;
        r.knob = knob, r.setting = setting, r.reference = "centre", r.is_default = is_default;
        const Encoded enc = encode(m.image, e, repeats_);
        const Errors err = errors_of(decode(enc, m.image, e), ref_centre_);
        r.rmse = err.rmse, r.mean_de00 = err.mean_de00;
        r.render_ms = m.ms, r.encode_ms = enc.ms, r.bytes = double(enc.data.size());
        say(fmt::format("  {:<18} {:<18} rmse {:.3e}  dE00 {:.3f}  encode {:.2f} ms  {:.0f} B",
                        knob, setting, r.rmse, r.mean_de00, r.encode_ms, r.bytes));
        rows.push_back(r);
    };
    for (const auto& e : encodings)
        encoded_row("encoding", e.name, e.name == kDefaultEncoding.name, by_format["rgba16f"], e);
    // The combination that matters: a finer render target buys nothing an 8-bit layer drops.
    const LayerEncoding& srgb8 = encodings[4];  // srgb8 tiles+zstd
    encoded_row("format+encoding", "rgba32f > f16", false, by_format["rgba32f"], kDefaultEncoding);
    encoded_row("format+encoding", "rgba16f > f16", true, by_format["rgba16f"], kDefaultEncoding);
    encoded_row("format+encoding", "rgba16f > srgb8", false, by_format["rgba16f"], srgb8);
    encoded_row("format+encoding", "rgba8 > srgb8", false, by_format["rgba8"], srgb8);
    return {};
}

Result<AccuracyReport> Sweep::run() {
    const auto t0 = Clock::now();
    if (s_.prop.kind != scene::Prop::Kind::kHemisphere)
        return make_error(ErrorCode::kUnsupported,
                          "bench accuracy needs the hemisphere prop: the exact reference is "
                          "the analytic hemisphere");
    if (s_.viewers.empty())
        return make_error(ErrorCode::kInvalidArgument, "bench accuracy: the scene has no viewer");
    spec_ = s_.material.specular;
    if (spec_.model == scene::SpecularModel::kNone) {
        if (s_.specular_presets.empty())
            return make_error(ErrorCode::kInvalidArgument,
                              "bench accuracy: the scene's material has no specular model and "
                              "there is no specular preset: the VD layer would be black");
        spec_ = s_.specular_presets.begin()->second;
    }
    const auto& v = s_.viewers.front();
    k_ = scene::eye_intrinsics(v);
    if (o_.quick)
        k_ = scaled_intrinsics(k_, 0.25);
    const double height = s_.viewing.heights_m.count(s_.viewing.default_height)
                              ? s_.viewing.heights_m.at(s_.viewing.default_height)
                              : 1.1;
    HS_ASSIGN_OR_RETURN(auto head, scene::viewing_pose(s_.viewing, 20.0, height));
    eye_ = scene::eye_poses(head, v.ipd_m)[1];

    AccuracyReport rep;
    rep.device = device_.name();
    rep.width = k_.width, rep.height = k_.height, rep.repeats = repeats_;
    say(fmt::format("VD layer {}x{} ({}), right eye at 20 deg, {} model, {} timed repeats, {}",
                    k_.width, k_.height, v.name, scene::to_string(spec_.model), repeats_,
                    rep.device));
    say("reference: exact hemisphere at pixel centres");
    HS_ASSIGN_OR_RETURN(ref_centre_, shading::reference_viewer(s_, spec_, k_, eye_));
    HS_TRY(tessellation(rep.rows));
    HS_TRY(render_scale(rep.rows));
    HS_TRY(samples_per_pixel(rep.rows));
    HS_TRY(lights(rep.rows));
    HS_TRY(formats_and_encodings(rep.rows));
    mark_pareto(rep.rows);
    rep.seconds = ms_since(t0) / 1000.0;
    return rep;
}

}  // namespace

double median(std::vector<double> v) {
    if (v.empty())
        return 0.0;
    std::sort(v.begin(), v.end());
    const size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

Result<AccuracyReport> run_accuracy(gpu::Device& device, const scene::Scene& scene,
                                    const AccuracyOptions& options) {
    return Sweep(device, scene, options).run();
}

void mark_pareto(std::vector<AccuracyRow>& rows) {
    for (auto& a : rows) {
        a.pareto = std::isfinite(a.error());
        for (const auto& b : rows) {
            if (&a == &b || b.knob != a.knob || !std::isfinite(b.error()))
                continue;
            const bool no_worse = b.cost_ms() <= a.cost_ms() && b.error() <= a.error();
            const bool better = b.cost_ms() < a.cost_ms() || b.error() < a.error();
            if (no_worse && better)
                a.pareto = false;
        }
    }
}

double hemisphere_geometric_error_mm(const scene::Hemisphere& h) {
    const scene::Mesh m = scene::tessellate_hemisphere(h);
    constexpr int kSteps = 6;  // barycentric grid: (kSteps + 1)(kSteps + 2) / 2 points
    double worst = 0;
    for (size_t t = 0; t + 2 < m.indices.size(); t += 3) {
        const glm::dvec3 a(m.positions[m.indices[t]]), b(m.positions[m.indices[t + 1]]),
            c(m.positions[m.indices[t + 2]]);
        for (int i = 0; i <= kSteps; ++i)
            for (int j = 0; i + j <= kSteps; ++j) {
                const double u = double(i) / kSteps, v = double(j) / kSteps;
                const glm::dvec3 p = a + u * (b - a) + v * (c - a);
                worst = std::max(worst, std::abs(glm::length(p - h.centre) - h.radius));
            }
    }
    return worst * 1e3;
}

std::string accuracy_csv(const AccuracyReport& rep) {
    std::string out =
        "knob,setting,reference,default,geometric_error_mm,rmse,mean_de00,render_ms,encode_ms,"
        "bytes,pareto,p50_px,p95_px,client_ms\n";
    for (const auto& r : rep.rows) {
        if (r.is_motion()) {
            out += fmt::format("{},{},{},{},,,,,,,{},{:.3f},{:.3f},{:.4f}\n", r.knob, r.setting,
                               r.reference, int(r.is_default), int(r.pareto), r.p50_px, r.p95_px,
                               r.client_ms);
            continue;
        }
        out += fmt::format(
            "{},{},{},{},{},{:.6e},{:.4f},{:.3f},{:.3f},{:.0f},{},,,\n", r.knob, r.setting,
            r.reference, int(r.is_default),
            r.geometric_error_mm < 0 ? std::string() : fmt::format("{:.4f}", r.geometric_error_mm),
            r.rmse, r.mean_de00, r.render_ms, r.encode_ms, r.bytes, int(r.pareto));
    }
    return out;
}

std::string accuracy_table(const AccuracyReport& rep) {
    std::string out = fmt::format(
        "VD layer {}x{}, medians of {} runs, {} ({:.0f} s)\n"
        "{:<18} {:<18} {:>4} {:>11} {:>8} {:>10} {:>10} {:>10} {:>9}  {}\n",
        rep.width, rep.height, rep.repeats, rep.device, rep.seconds, "knob", "setting", "ref",
        "rmse", "dE00", "render ms", "encode ms", "bytes", "geom mm", "");
    std::string knob;
    bool motion_header = false;
    for (const auto& r : rep.rows) {
        if (r.is_motion()) {
            if (!motion_header)
                out += fmt::format("\n{:<18} {:<18} {:>5} {:>10} {:>8} {:>10}\n", "knob", "setting",
                                   "ref", "p50 px", "p95 px", "client ms");
            motion_header = true;
            out += fmt::format("{:<18} {:<18} {:>5} {:>10.1f} {:>8.1f} {:>10.3f}  {}{}\n", r.knob,
                               r.setting, r.reference, r.p50_px, r.p95_px, r.client_ms,
                               r.pareto ? "pareto" : "", r.is_default ? " default" : "");
            continue;
        }
        if (r.knob != knob && !knob.empty())
            out += "\n";
        knob = r.knob;
        out += fmt::format(
            "{:<18} {:<18} {:>4} {:>11.3e} {:>8.3f} {:>10.2f} {:>10.2f} {:>10.0f} {:>9}  {}{}\n",
            r.knob, r.setting, r.reference.substr(0, 4), r.rmse, r.mean_de00, r.render_ms,
            r.encode_ms, r.bytes,
            r.geometric_error_mm < 0 ? std::string() : fmt::format("{:.3f}", r.geometric_error_mm),
            r.pareto ? "pareto" : "", r.is_default ? " default" : "");
    }
    return out;
}

Figure accuracy_plot(const AccuracyReport& rep) {
    std::vector<std::string> knobs;
    for (const auto& r : rep.rows)
        if (std::find(knobs.begin(), knobs.end(), r.knob) == knobs.end())
            knobs.push_back(r.knob);
    std::vector<Figure> panels;
    for (const auto& knob : knobs) {
        Series all{"setting", {}, {}, {70, 110, 200}, true};
        all.lines = false;
        Series front{"Pareto front", {}, {}, {215, 60, 40}, true};
        std::vector<const AccuracyRow*> fr;
        for (const auto& r : rep.rows) {
            if (r.knob != knob)
                continue;
            all.x.push_back(r.cost_ms());
            all.y.push_back(r.error());
            all.labels.push_back(r.setting + (r.is_default ? " *" : ""));
            if (r.pareto)
                fr.push_back(&r);
        }
        std::sort(fr.begin(), fr.end(),
                  [](auto* a, auto* b) { return a->cost_ms() < b->cost_ms(); });
        for (const auto* r : fr) front.x.push_back(r->cost_ms()), front.y.push_back(r->error());
        PlotOptions po;
        po.title = knob;
        const bool motion = std::any_of(rep.rows.begin(), rep.rows.end(), [&](const auto& r) {
            return r.knob == knob && r.is_motion();
        });
        po.x_label = motion ? "client ms per stereo frame" : "ms per layer (render + encode), log";
        po.y_label = motion ? "p95 highlight error, profile px" : "RMSE, linear radiance, log";
        po.log_y = !motion;
        po.log_x = !motion;
        po.width = 520, po.height = 340;
        panels.push_back(line_plot({front, all}, po));
    }
    std::vector<Figure> rows_of_panels;
    for (size_t i = 0; i < panels.size(); i += 2)
        rows_of_panels.push_back(hstack(std::vector<Figure>(
            panels.begin() + i, panels.begin() + std::min(panels.size(), i + 2))));
    return vstack(rows_of_panels);
}

}  // namespace hs::bench
