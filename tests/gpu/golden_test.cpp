// Golden images: small renders of one image per specular model, per effect and per hard case,
// compared pixel by pixel with the files in tests/data/golden/. golden.json there says how each
// is rendered (a merge patch of the default scene and the pass) and its tolerance
// (docs/SHADING.md, "Golden images"). HYSAR_REGEN_GOLDEN=1 writes the goldens instead of
// comparing (scripts/regen_golden.sh); a failed comparison writes the render, the golden and
// their difference as PNG files under HYSAR_GOLDEN_FAILURES (default: the build tree's
// tests/golden-failures/). HYSAR_GOLDEN_DIR reads (and writes) the goldens in another folder.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <span>
#include <sstream>
#include <stdexcept>

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>
#include <glm/gtc/packing.hpp>
#include <nlohmann/json.hpp>

#include "gpu_fixture.hpp"
#include "scene/camera.hpp"
#include "scene/config.hpp"

using namespace hs;
using namespace hs::test;
namespace fs = std::filesystem;
using json = nlohmann::json;

#ifndef HYSAR_GOLDEN_FAILURE_DIR
#define HYSAR_GOLDEN_FAILURE_DIR "golden-failures"
#endif

namespace {

// The goldens and golden.json: tests/data/golden/, or HYSAR_GOLDEN_DIR (a scratch copy).
fs::path golden_dir() {
    const char* e = std::getenv("HYSAR_GOLDEN_DIR");
    return (e && *e) ? fs::path(e) : fs::path(HYSAR_SOURCE_DIR) / "tests" / "data" / "golden";
}

bool regenerating() {
    const char* e = std::getenv("HYSAR_REGEN_GOLDEN");
    return e && std::string(e) == "1";
}

fs::path failure_dir() {
    const char* e = std::getenv("HYSAR_GOLDEN_FAILURES");
    return (e && *e) ? fs::path(e) : fs::path(HYSAR_GOLDEN_FAILURE_DIR);
}

// One manifest entry; `error` is set instead when the manifest could not be read.
struct GoldenEntry {
    std::string name;
    json entry;
    std::string error;
};

void PrintTo(const GoldenEntry& g, std::ostream* os) {
    *os << g.name;
}

json read_manifest() {
    const fs::path manifest = golden_dir() / "golden.json";
    std::ifstream in(manifest);
    if (!in)
        throw std::runtime_error(manifest.string() + ": cannot be read");
    try {
        return json::parse(in);
    } catch (const json::exception& e) {
        throw std::runtime_error(manifest.string() + ": " + e.what());
    }
}

// The manifest's images, or one entry carrying the reason they could not be listed (so the
// failure is a failed test, not a binary that lists no tests).
std::vector<GoldenEntry> load_manifest() {
    std::vector<GoldenEntry> out;
    try {
        const json m = read_manifest();
        for (const json& e : m.at("images"))
            out.push_back({e.at("name").get<std::string>(), e, ""});
    } catch (const std::exception& e) {
        return {{"manifest", json(), e.what()}};
    }
    return out;
}

// Refuses keys the reader does not know (a misspelt field would silently render a default).
void only_keys(const json& o, const std::string& where, std::initializer_list<const char*> keys) {
    if (!o.is_object())
        throw std::runtime_error(where + ": expected an object");
    for (auto it = o.begin(); it != o.end(); ++it) {
        bool known = false;
        for (const char* k : keys) known = known || it.key() == k;
        if (!known)
            throw std::runtime_error(where + ": unknown key \"" + it.key() + "\"");
    }
}

struct Tolerance {
    double max_rel = 0, max_abs = 0, rmse_rel = 0, rmse_abs = 0;
    // Pixels on the golden's silhouette (a black and a lit pixel in its 3 x 3 neighbourhood) that
    // may exceed the max bound, as a fraction of all pixels; they still count in the RMSE.
    double silhouette_fraction = 0;
};

Tolerance read_bounds(const json& t) {
    return {t.at("max_abs").at("rel").get<double>(), t.at("max_abs").at("abs").get<double>(),
            t.at("rmse").at("rel").get<double>(), t.at("rmse").at("abs").get<double>()};
}

// The manifest, read once for the tests that need its top-level fields.
const json& manifest() {
    static const json m = read_manifest();
    return m;
}

// Renders from a driver other than the goldens' (golden.json "other_driver") are held to its
// bounds: rasterisation's sub-pixel precision and fp32 transcendentals legitimately differ.
bool generating_driver() {
    const json& m = manifest();
    const std::string family = m.at("other_driver").at("generating_device_contains");
    return device().name().find(family) != std::string::npos;
}

Tolerance other_driver_tolerance() {
    const json& m = manifest();
    const json& o = m.at("other_driver");
    only_keys(o, "golden.json other_driver",
              {"generating_device_contains", "max_abs", "rmse", "silhouette_fraction", "measured",
               "why"});
    Tolerance t = read_bounds(o);
    t.silhouette_fraction = o.at("silhouette_fraction").get<double>();
    return t;
}

Tolerance tolerance_of(const GoldenEntry& g) {
    const json& t = g.entry.at("tolerance");
    only_keys(t, g.name + ".tolerance", {"max_abs", "rmse", "why"});
    return read_bounds(t);
}

gpu::ColorFormat format_of(const std::string& f) {
    if (f == "rgba16f")
        return gpu::ColorFormat::kRgba16Float;
    if (f == "rgba32f")
        return gpu::ColorFormat::kRgba32Float;
    throw std::runtime_error("format: expected \"rgba16f\" or \"rgba32f\", got \"" + f + "\"");
}

std::string joined(const std::vector<std::string>& v) {
    std::string s;
    for (const auto& x : v) s += (s.empty() ? "" : ", ") + x;
    return "[" + s + "]";
}

// What one golden's pixels are compared by.
struct Comparison {
    double peak = 0;  // the golden's largest finite R, G or B
    double bound = 0, max_abs = 0, rmse = 0, rmse_bound = 0;
    size_t non_finite = 0;       // in the render
    size_t silhouette_over = 0;  // silhouette pixels over the bound, left out of max_abs
    size_t silhouette_allowed = 0;
    uint32_t x = 0, y = 0, channel = 0;  // the worst pixel (or the first non-finite one)
    float render = 0, golden = 0;
};

Comparison compare(const ImageRgba32f& render, const ImageRgba32f& golden, const Tolerance& t) {
    Comparison c;
    for (size_t i = 0; i < golden.pixels.size(); ++i)
        if (i % 4 != 3 && std::isfinite(golden.pixels[i]))
            c.peak = std::max(c.peak, double(golden.pixels[i]));
    c.bound = t.max_rel * c.peak + t.max_abs;
    c.rmse_bound = t.rmse_rel * c.peak + t.rmse_abs;
    const uint32_t w = golden.width, h = golden.height;
    c.silhouette_allowed = size_t(t.silhouette_fraction * double(size_t(w) * h));
    auto lit = [&](uint32_t x, uint32_t y) {
        const float* p = &golden.pixels[(size_t(y) * w + x) * 4];
        return p[0] != 0 || p[1] != 0 || p[2] != 0;
    };
    auto on_silhouette = [&](uint32_t px) {
        const uint32_t x = px % w, y = px / w;
        const bool here = lit(x, y);
        for (uint32_t yy = y ? y - 1 : 0; yy <= std::min(y + 1, h - 1); ++yy)
            for (uint32_t xx = x ? x - 1 : 0; xx <= std::min(x + 1, w - 1); ++xx)
                if (lit(xx, yy) != here)
                    return true;
        return false;
    };
    double sum2 = 0;
    size_t n = 0;
    uint32_t last_over = UINT32_MAX;  // a pixel counts once, whichever channels are over
    for (size_t i = 0; i < render.pixels.size(); ++i) {
        if (i % 4 == 3)
            continue;
        const float r = render.pixels[i], g = golden.pixels[i];
        const uint32_t px = uint32_t(i / 4);
        if (!std::isfinite(r) || !std::isfinite(g)) {
            if (c.non_finite++ == 0)
                c.x = px % render.width, c.y = px / render.width, c.channel = i % 4, c.render = r,
                c.golden = g, c.max_abs = INFINITY;
            continue;
        }
        const double d = std::abs(double(r) - double(g));
        sum2 += d * d;
        ++n;
        if (d > c.bound && c.silhouette_allowed > 0 && on_silhouette(px)) {
            c.silhouette_over += px != last_over;
            last_over = px;
            if (c.silhouette_over <= c.silhouette_allowed)
                continue;
        }
        if (d > c.max_abs && c.non_finite == 0)
            c.max_abs = d, c.x = px % render.width, c.y = px / render.width, c.channel = i % 4,
            c.render = r, c.golden = g;
    }
    c.rmse = n ? std::sqrt(sum2 / double(n)) : 0.0;
    return c;
}

class GoldenImage : public GpuTest, public ::testing::WithParamInterface<GoldenEntry> {
protected:
    struct Rendered {
        ImageRgba32f image;
        std::vector<std::string> effects;
        bool has_effects = false;  // false: the pass reports none (layers)
    };

    // Renders `g` as golden.json describes it; throws std::runtime_error naming what failed.
    Rendered render(const GoldenEntry& g) {
        const json& e = g.entry;
        only_keys(e, g.name, {"name", "file", "shows", "render", "scene_patch", "tolerance"});
        json scene_json = json::parse(scene::default_scene_json());
        if (e.contains("scene_patch"))
            scene_json.merge_patch(e.at("scene_patch"));
        auto s = scene::parse_scene(scene_json.dump(), "golden.json: " + g.name + ".scene_patch",
                                    golden_dir());
        if (!s.ok())
            throw std::runtime_error(s.error().message);
        const json& r = e.at("render");
        only_keys(r, g.name + ".render",
                  {"pass", "preset", "angle_deg", "height", "eye", "eye_div", "format",
                   "area_light_samples", "encoding", "sparse", "effects"});
        render::RendererCreateInfo info;
        info.format = format_of(r.value("format", "rgba16f"));
        info.area_light_samples = r.value("area_light_samples", render::kDefaultAreaLightSamples);
        auto made = render::Renderer::create(device(), s.value(), info);
        if (!made.ok())
            throw std::runtime_error(made.error().message);
        render::Renderer& renderer = *made.value();
        const std::string pass = r.at("pass").get<std::string>();
        auto finish = [](Result<render::RenderResult> out) {
            if (!out.ok())
                throw std::runtime_error(out.error().message);
            return Rendered{std::move(out->image), out->report.effects, true};
        };
        if (pass == "projector")
            return finish(renderer.render_projector());

        const scene::Specular spec = r.contains("preset")
                                         ? s->specular_presets.at(r.at("preset").get<std::string>())
                                         : s->material.specular;
        const scene::Intrinsics k = small_eye(r.at("eye_div").get<uint32_t>());
        auto head = scene::viewing_pose(s->viewing, r.at("angle_deg").get<double>(),
                                        s->viewing.heights_m.at(r.at("height").get<std::string>()));
        if (!head.ok())
            throw std::runtime_error(head.error().message);
        const std::string which = r.at("eye").get<std::string>();
        if (which != "left" && which != "right")
            throw std::runtime_error(g.name + ".render.eye: expected \"left\" or \"right\"");
        const scene::Pose eye =
            scene::eye_poses(head.value(), s->viewers.front().ipd_m)[which == "right" ? 1 : 0];
        if (pass == "eye")
            return finish(renderer.render_eye(spec, k, eye));
        if (pass == "eye_diffuse")
            return finish(renderer.render_eye_diffuse(k, eye));
        if (pass != "layer")
            throw std::runtime_error(g.name +
                                     ".render.pass: expected eye, eye_diffuse, projector "
                                     "or layer, got \"" +
                                     pass + "\"");

        const std::string enc_name = r.at("encoding").get<std::string>();
        if (enc_name != "srgb8" && enc_name != "half")
            throw std::runtime_error(g.name + ".render.encoding: expected srgb8 or half");
        const auto enc =
            enc_name == "srgb8" ? render::LayerEncoding::kSrgb8 : render::LayerEncoding::kHalf;
        auto t = gpu::RenderTarget::create(device(), k.width, k.height,
                                           render::layer_target_format(enc), "golden layer");
        if (!t.ok())
            throw std::runtime_error(t.error().message);
        render::Renderer::LayerRequest req{spec, k, eye, enc, &t.value()};
        req.sparse = r.at("sparse").get<bool>();
        auto plans = renderer.render_layers(std::span(&req, 1));
        if (!plans.ok())
            throw std::runtime_error(plans.error().message);
        // As the wire carries it: the rendered rectangle's parts, black elsewhere; sRGB8 as its
        // codes.
        Rendered out{ImageRgba32f::zeros(k.width, k.height), {}, false};
        const std::vector<uint8_t> bytes = render::Renderer::layer_bytes(*t, (*plans)[0]);
        const uint8_t* data = bytes.data();
        for (size_t i = 0; i < size_t(k.width) * k.height * 4; ++i) {
            if (enc == render::LayerEncoding::kSrgb8) {
                out.image.pixels[i] = float(data[i]);
            } else {
                uint16_t h;
                std::memcpy(&h, data + 2 * i, 2);
                out.image.pixels[i] = glm::unpackHalf1x16(h);
            }
        }
        return out;
    }
};

// Writes the render, the golden and their difference as PNG files (and the render as EXR, to
// inspect or adopt); returns a message listing the paths.
std::string write_artefacts(const std::string& name, const ImageRgba32f& render,
                            const ImageRgba32f* golden, const Comparison* c) {
    const fs::path dir = failure_dir();
    std::error_code ec;
    fs::create_directories(dir, ec);
    std::ostringstream msg;
    msg << "\n  artefacts:";
    // Both drawn with the golden's peak as white, so they look the same when they agree.
    float white = c && c->peak > 0 ? float(c->peak) : 0.0f;
    if (white == 0)
        for (size_t i = 0; i < render.pixels.size(); ++i)
            if (i % 4 != 3 && std::isfinite(render.pixels[i]))
                white = std::max(white, render.pixels[i]);
    auto put = [&](const fs::path& path, Result<void> written) {
        msg << "\n    " << path.string()
            << (written.ok() ? "" : " (" + written.error().message + ")");
        std::printf("[golden] wrote %s\n", path.string().c_str());
    };
    put(dir / (name + ".render.png"),
        write_png(dir / (name + ".render.png"), tonemap_srgb8(render, white > 0 ? white : 1.0f)));
    put(dir / (name + ".render.exr"), write_exr(dir / (name + ".render.exr"), render));
    if (golden) {
        put(dir / (name + ".golden.png"),
            write_png(dir / (name + ".golden.png"), tonemap_srgb8(*golden, white > 0 ? white : 1)));
    }
    if (golden && c && golden->width == render.width && golden->height == render.height) {
        // |render - golden| with the bound as white: a channel over the tolerance is full on,
        // one within it is dimmer; NaN or Inf in either is magenta.
        ImageRgba32f diff = ImageRgba32f::zeros(render.width, render.height);
        for (size_t i = 0; i < diff.pixels.size(); ++i) {
            const float d = std::abs(render.pixels[i] - golden->pixels[i]);
            diff.pixels[i] = i % 4 == 3 ? 1.0f : (std::isfinite(d) ? d : NAN);
        }
        for (size_t i = 0; i < diff.pixels.size(); i += 4)
            if (std::isnan(diff.pixels[i]) || std::isnan(diff.pixels[i + 1]) ||
                std::isnan(diff.pixels[i + 2]))
                diff.pixels[i] = NAN;
        put(dir / (name + ".diff.png"),
            write_png(dir / (name + ".diff.png"), tonemap_srgb8(diff, float(c->bound))));
        msg << " (diff.png: |render - golden| with white at the bound, " << c->bound << ")";
    }
    return msg.str();
}

// A golden file: R, G, B as half floats (ZIP) when every value is exactly a half, as an rgba16f
// target's and the layer encodings' are (lossless, half the size of write_exr's 32-bit floats);
// otherwise write_exr. read_exr reads both.
Result<void> write_golden(const fs::path& path, const ImageRgba32f& image) {
    std::vector<uint16_t> halves(size_t(image.width) * image.height * 3);
    for (size_t p = 0; p < halves.size() / 3; ++p)
        for (size_t c = 0; c < 3; ++c) {
            const float v = image.pixels[p * 4 + c];
            halves[p * 3 + c] = glm::packHalf1x16(v);
            if (glm::unpackHalf1x16(halves[p * 3 + c]) != v)
                return write_exr(path, image);
        }
    try {
        Imf::Header header(int(image.width), int(image.height));
        header.compression() = Imf::ZIP_COMPRESSION;
        Imf::FrameBuffer fb;
        const char* names[] = {"R", "G", "B"};
        for (int c = 0; c < 3; ++c) {
            header.channels().insert(names[c], Imf::Channel(Imf::HALF));
            fb.insert(names[c],
                      Imf::Slice(Imf::HALF, reinterpret_cast<char*>(halves.data() + c),
                                 3 * sizeof(uint16_t), 3 * sizeof(uint16_t) * image.width));
        }
        Imf::OutputFile file(path.c_str(), header);
        file.setFrameBuffer(fb);
        file.writePixels(int(image.height));
    } catch (const std::exception& e) {
        return make_error(ErrorCode::kIo, path.string() + ": could not write EXR: " + e.what());
    }
    return {};
}

const char* kChannel = "RGBA";

TEST_P(GoldenImage, MatchesTheStoredRender) {
    const GoldenEntry& g = GetParam();
    ASSERT_EQ(g.error, "") << "golden.json could not be read";
    Rendered out;
    Tolerance tol;
    bool generating = true;
    try {
        out = render(g);
        generating = generating_driver();
        tol = generating ? tolerance_of(g) : other_driver_tolerance();
    } catch (const std::exception& e) {
        FAIL() << g.name << ": " << e.what();
    }
    const json& r = g.entry.at("render");
    if (r.contains("effects")) {
        ASSERT_TRUE(out.has_effects) << g.name << ": this pass reports no effects to check";
        const std::string want = joined(r.at("effects").get<std::vector<std::string>>());
        ASSERT_EQ(joined(out.effects), want)
            << g.name << ": the pass compiled other terms in than golden.json says";
    }
    const std::string file = g.entry.at("file").get<std::string>();
    ASSERT_EQ(file, g.name + ".exr") << "golden.json: a golden's file is its name + .exr";
    const fs::path path = golden_dir() / file;
    size_t non_finite = 0;
    double peak = 0;
    for (size_t i = 0; i < out.image.pixels.size(); ++i)
        if (i % 4 != 3) {
            non_finite += !std::isfinite(out.image.pixels[i]);
            if (std::isfinite(out.image.pixels[i]))
                peak = std::max(peak, double(out.image.pixels[i]));
        }

    if (regenerating()) {
        ASSERT_EQ(non_finite, 0u) << g.name << ": the render has NaN or Inf; not written";
        ASSERT_GT(peak, 0.0) << g.name << ": the render is black, a golden that proves nothing";
        auto w = write_golden(path, out.image);
        ASSERT_TRUE(w.ok()) << w.error().message;
        std::printf("[golden] regenerated %s (%u x %u, peak %.6g, effects %s)\n",
                    path.string().c_str(), out.image.width, out.image.height, peak,
                    out.has_effects ? joined(out.effects).c_str() : "-");
        return;
    }

    if (!fs::exists(path)) {
        FAIL() << g.name << ": the golden " << path.string()
               << " does not exist. Create it with scripts/regen_golden.sh (renders every golden "
                  "and writes it there), look at it, and commit it with a line saying why."
               << write_artefacts(g.name, out.image, nullptr, nullptr);
    }
    auto golden = read_exr(path);
    ASSERT_TRUE(golden.ok()) << golden.error().message;
    if (golden->width != out.image.width || golden->height != out.image.height) {
        FAIL() << g.name << ": the render is " << out.image.width << " x " << out.image.height
               << ", the golden " << path.string() << " is " << golden->width << " x "
               << golden->height << write_artefacts(g.name, out.image, &golden.value(), nullptr);
    }
    // Goldens store R, G, B: compare those (read_exr gives alpha 1).
    const Comparison c = compare(out.image, golden.value(), tol);
    ASSERT_GT(c.peak, 0.0) << g.name << ": the golden is black, it proves nothing";
    std::ostringstream where;
    where << " at pixel (x " << c.x << ", y " << c.y << ") channel " << kChannel[c.channel]
          << ": render " << c.render << ", golden " << c.golden;
    const bool ok = c.non_finite == 0 && c.max_abs <= c.bound && c.rmse <= c.rmse_bound &&
                    c.silhouette_over <= c.silhouette_allowed;
    std::printf(
        "[golden] %-30s peak %.4g  max |diff| %.3g (bound %.3g)  rmse %.3g (bound %.3g)%s\n",
        g.name.c_str(), c.peak, c.max_abs, c.bound, c.rmse, c.rmse_bound,
        generating
            ? ""
            : (", other driver, silhouette pixels over " + std::to_string(c.silhouette_over) +
               " (allowed " + std::to_string(c.silhouette_allowed) + ")")
                  .c_str());
    if (ok)
        return;
    std::ostringstream msg;
    msg.precision(7);
    msg << g.name << " differs from " << path.string() << " (device " << device().name()
        << (generating ? ", the goldens' driver" : ", another driver: golden.json other_driver")
        << "):";
    if (c.silhouette_over > c.silhouette_allowed)
        msg << "\n  " << c.silhouette_over << " silhouette pixels over the bound; "
            << c.silhouette_allowed << " allowed";
    if (c.non_finite)
        msg << "\n  " << c.non_finite << " NaN or Inf value(s), the first" << where.str();
    else
        msg << "\n  max |render - golden| = " << c.max_abs << where.str() << "; bound "
            << tol.max_rel << " x peak " << c.peak << " + " << tol.max_abs << " = " << c.bound;
    msg << "\n  RMSE " << c.rmse << "; bound " << tol.rmse_rel << " x peak + " << tol.rmse_abs
        << " = " << c.rmse_bound;
    msg << write_artefacts(g.name, out.image, &golden.value(), &c);
    msg << "\n  If the change is intended, regenerate with scripts/regen_golden.sh and say why "
           "in the commit message.";
    ADD_FAILURE() << msg.str();
}

INSTANTIATE_TEST_SUITE_P(Golden, GoldenImage, ::testing::ValuesIn(load_manifest()),
                         [](const ::testing::TestParamInfo<GoldenEntry>& info) {
                             std::string n = info.param.name;
                             for (char& ch : n)
                                 if (!std::isalnum(static_cast<unsigned char>(ch)))
                                     ch = '_';
                             return n;
                         });

// The other-driver rule: only pixels on the golden's silhouette may exceed the bound, and only
// up to their allowance; every other pixel is held to the bound.
TEST(GoldenCompare, OnlySilhouettePixelsMayExceedTheBoundAndOnlyUpToTheirAllowance) {
    // A 10 x 10 golden lit (0.5) in the square [3, 7) x [3, 7).
    ImageRgba32f golden = ImageRgba32f::zeros(10, 10);
    for (uint32_t y = 3; y < 7; ++y)
        for (uint32_t x = 3; x < 7; ++x) golden.set(x, y, {0.5f, 0.5f, 0.5f, 1});
    const Tolerance loose{0.01, 1e-3, 1.0, 1.0, 0.02};  // 2 of 100 pixels may exceed
    Tolerance tight = loose;
    tight.silhouette_fraction = 0;
    // One pixel beside the square lit on the render (a coverage difference).
    ImageRgba32f one = golden;
    one.set(2, 4, {0.5f, 0.5f, 0.5f, 1});
    Comparison c = compare(one, golden, loose);
    EXPECT_EQ(c.silhouette_over, 1u);
    EXPECT_EQ(c.max_abs, 0.0);
    EXPECT_EQ(compare(one, golden, tight).max_abs, 0.5) << "no allowance on the goldens' driver";
    // Three such pixels: over the allowance of two, the third counts.
    ImageRgba32f three = one;
    three.set(7, 4, {0.5f, 0.5f, 0.5f, 1});
    three.set(4, 2, {0.5f, 0.5f, 0.5f, 1});
    c = compare(three, golden, loose);
    EXPECT_EQ(c.silhouette_over, 3u);
    EXPECT_GT(c.silhouette_over, c.silhouette_allowed);
    EXPECT_EQ(c.max_abs, 0.5);
    // Inside the square, away from any black pixel: never exempt.
    ImageRgba32f inner = golden;
    inner.set(5, 5, {0.6f, 0.5f, 0.5f, 1});
    c = compare(inner, golden, loose);
    EXPECT_EQ(c.silhouette_over, 0u);
    EXPECT_NEAR(c.max_abs, 0.1, 1e-6);
    EXPECT_GT(c.max_abs, c.bound);
}

// The manifest itself: unique names, each file its name + .exr, and no golden file in the
// folder that the manifest does not list (it would never be compared).
TEST(GoldenManifest, ListsEveryGoldenOnce) {
    json m;
    try {
        m = read_manifest();
    } catch (const std::exception& e) {
        FAIL() << e.what();
    }
    std::set<std::string> files;
    for (const json& e : m.at("images")) {
        const std::string name = e.at("name").get<std::string>();
        for (char ch : name)
            EXPECT_TRUE(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_')
                << "golden.json: name \"" << name << "\" must be letters, digits and _";
        EXPECT_EQ(e.at("file").get<std::string>(), name + ".exr");
        EXPECT_TRUE(files.insert(name + ".exr").second) << "golden.json lists " << name << " twice";
        EXPECT_TRUE(e.contains("shows") && e.contains("tolerance") &&
                    e.at("tolerance").contains("why"))
            << name << ": every golden says what it shows and why its tolerance is what it is";
    }
    for (const auto& f : fs::directory_iterator(golden_dir())) {
        if (f.path().extension() != ".exr")
            continue;
        EXPECT_TRUE(files.count(f.path().filename().string()))
            << f.path().string() << " is not listed in golden.json: it is never compared";
    }
}

}  // namespace
