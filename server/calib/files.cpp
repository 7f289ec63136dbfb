#include "calib/files.hpp"

#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <tuple>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "scene/config.hpp"

namespace hs::calib {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

Result<void> write_json(const fs::path& file, const json& j) {
    std::ofstream out(file);
    out << j.dump(2) << "\n";
    if (!out)
        return make_error(ErrorCode::kIo, fmt::format("{}: cannot write", file.string()));
    return {};
}

Result<json> read_json(const fs::path& file) {
    HS_ASSIGN_OR_RETURN(std::string text, read_text_file(file));
    try {
        return json::parse(text);
    } catch (const json::exception& e) {
        return make_error(ErrorCode::kParse,
                          fmt::format("{}: not JSON: {}", file.string(), e.what()));
    }
}

// A field that is missing or not what it must be; from_json names the file.
struct FieldError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

constexpr double kMaxDevicePixels = scene::kMaxImageSide;  // a device side, in pixels

const json& field(const json& j, const std::string& key, const std::string& name) {
    if (!j.is_object() || !j.contains(key))
        throw FieldError(fmt::format("no \"{}\"", name));
    return j.at(key);
}

double finite_number(const json& v, const std::string& name) {
    if (!v.is_number())
        throw FieldError(fmt::format("{} is {}, not a finite number", name,
                                     v.is_null() ? "null (a NaN or infinity written as JSON)"
                                                 : std::string("a ") + v.type_name()));
    const double d = v.get<double>();
    if (!std::isfinite(d))
        throw FieldError(fmt::format("{} is {}, not a finite number", name, d));
    return d;
}

double finite_number(const json& j, const std::string& key, const std::string& name) {
    return finite_number(field(j, key, name), name);
}

const json& array_of(const json& j, const std::string& key, size_t n, const std::string& name) {
    const json& a = field(j, key, name);
    if (!a.is_array() || a.size() != n)
        throw FieldError(fmt::format("{} is not an array of {}", name, n));
    return a;
}

std::pair<uint32_t, uint32_t> device_size(const json& j, const std::string& key) {
    const json& a = array_of(j, key, 2, key);
    uint32_t wh[2];
    for (int i = 0; i < 2; ++i) {
        const std::string name = fmt::format("{}[{}]", key, i);
        const double v = finite_number(a.at(i), name);
        if (!(v >= 1 && v <= kMaxDevicePixels && v == std::floor(v)))
            throw FieldError(fmt::format("{} is {}, not a whole number of pixels in [1, {}]", name,
                                         v, kMaxDevicePixels));
        wh[i] = uint32_t(v);
    }
    return {wh[0], wh[1]};
}

// Runs `fn` on a parsed file; a missing key, a wrong type or a FieldError becomes an error
// naming the file (and the field).
template <typename T, typename Fn>
Result<T> from_json(const fs::path& file, const char* kind, Fn fn) {
    HS_ASSIGN_OR_RETURN(json j, read_json(file));
    try {
        if (!j.is_object() || j.value("kind", std::string()) != kind)
            return make_error(ErrorCode::kParse,
                              fmt::format("{}: not a {} file (its \"kind\" is not \"{}\")",
                                          file.string(), kind, kind));
        return fn(j);
    } catch (const FieldError& e) {
        return make_error(ErrorCode::kParse, fmt::format("{}: {}", file.string(), e.what()));
    } catch (const json::exception& e) {
        return make_error(ErrorCode::kParse,
                          fmt::format("{}: malformed {} file: {}", file.string(), kind, e.what()));
    }
}

Result<void> check_map_image(const fs::path& file, const ImageRgba32f& img, uint32_t w,
                             uint32_t h) {
    if (img.width != w || img.height != h)
        return make_error(ErrorCode::kParse,
                          fmt::format("{}: the image is {}x{}, its JSON says {}x{}", file.string(),
                                      img.width, img.height, w, h));
    return {};
}

}  // namespace

Result<std::string> read_text_file(const fs::path& file) {
    std::ifstream in(file);
    if (!in)
        return make_error(ErrorCode::kNotFound, fmt::format("{}: cannot open", file.string()));
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

Result<void> save_lut(const fs::path& dir, const DeviceLut& lut, const DecodeOptions& o) {
    ImageRgba32f img = ImageRgba32f::zeros(lut.camera_width, lut.camera_height);
    for (size_t i = 0; i < lut.state.size(); ++i) {
        img.pixels[i * 4] = lut.x[i];
        img.pixels[i * 4 + 1] = lut.y[i];
        img.pixels[i * 4 + 2] = lut.state[i] * 0.5f;
        img.pixels[i * 4 + 3] = 1;
    }
    HS_TRY(write_exr(dir / "lut.exr", img));
    return write_json(dir / "lut.json", {{"kind", "hysar-lut"},
                                         {"camera", {lut.camera_width, lut.camera_height}},
                                         {"device", {lut.device_width, lut.device_height}},
                                         {"black_threshold", o.black_threshold},
                                         {"white_threshold", o.white_threshold},
                                         {"lit", lut.lit},
                                         {"valid", lut.valid}});
}

Result<DeviceLut> load_lut(const fs::path& dir) {
    HS_ASSIGN_OR_RETURN(DeviceLut lut, load_lut_sizes(dir));
    HS_ASSIGN_OR_RETURN(ImageRgba32f img, read_exr(dir / "lut.exr"));
    HS_TRY(check_map_image(dir / "lut.exr", img, lut.camera_width, lut.camera_height));
    const size_t n = size_t(img.width) * img.height;
    lut.x.resize(n), lut.y.resize(n), lut.state.resize(n);
    for (size_t i = 0; i < n; ++i) {
        const float s = img.pixels[i * 4 + 2];
        lut.state[i] = s > 0.75f ? DeviceLut::kValid
                                 : (s > 0.25f ? DeviceLut::kAmbiguous : DeviceLut::kShadow);
        const float x = img.pixels[i * 4], y = img.pixels[i * 4 + 1];
        if (lut.state[i] == DeviceLut::kValid &&
            !(x >= 0 && y >= 0 && x < lut.device_width && y < lut.device_height))
            return make_error(ErrorCode::kParse,
                              fmt::format("{}: camera pixel ({}, {}) maps to device ({}, {}), "
                                          "outside the {}x{} device",
                                          (dir / "lut.exr").string(), i % img.width, i / img.width,
                                          x, y, lut.device_width, lut.device_height));
        lut.x[i] = lut.state[i] == DeviceLut::kValid ? x : NAN;
        lut.y[i] = lut.state[i] == DeviceLut::kValid ? y : NAN;
        lut.lit += lut.state[i] != DeviceLut::kShadow;
        lut.valid += lut.state[i] == DeviceLut::kValid;
    }
    return lut;
}

Result<DeviceLut> load_lut_sizes(const fs::path& dir) {
    return from_json<DeviceLut>(dir / "lut.json", "hysar-lut", [](const json& j) -> DeviceLut {
        DeviceLut l;
        std::tie(l.camera_width, l.camera_height) = device_size(j, "camera");
        std::tie(l.device_width, l.device_height) = device_size(j, "device");
        return l;
    });
}

Result<void> save_inverse(const fs::path& dir, const InverseMap& m) {
    ImageRgba32f img = ImageRgba32f::zeros(m.device_width, m.device_height);
    for (size_t i = 0; i < m.valid.size(); ++i) {
        img.pixels[i * 4] = m.x[i];
        img.pixels[i * 4 + 1] = m.y[i];
        img.pixels[i * 4 + 2] = m.valid[i];
        img.pixels[i * 4 + 3] = 1;
    }
    HS_TRY(write_exr(dir / "inverse.exr", img));
    json cv = json::array();
    for (const auto& s : m.cv)
        cv.push_back({{"bandwidth", s.bandwidth}, {"rmse_px", s.rmse_px}, {"scored", s.scored}});
    return write_json(dir / "inverse.json", {{"kind", "hysar-inverse"},
                                             {"camera", {m.camera_width, m.camera_height}},
                                             {"device", {m.device_width, m.device_height}},
                                             {"bandwidth", m.bandwidth},
                                             {"cross_validation", cv},
                                             {"estimated", m.estimated},
                                             {"holes_inside", m.holes_inside},
                                             {"samples", m.samples},
                                             {"merged", m.merged},
                                             {"ms", m.ms}});
}

Result<InverseMap> load_inverse(const fs::path& dir) {
    HS_ASSIGN_OR_RETURN(InverseMap m,
                        (from_json<InverseMap>(dir / "inverse.json", "hysar-inverse",
                                               [](const json& j) -> InverseMap {
                                                   InverseMap r;
                                                   r.camera_width = j.at("camera").at(0);
                                                   r.camera_height = j.at("camera").at(1);
                                                   r.device_width = j.at("device").at(0);
                                                   r.device_height = j.at("device").at(1);
                                                   r.bandwidth = j.at("bandwidth");
                                                   return r;
                                               })));
    HS_ASSIGN_OR_RETURN(ImageRgba32f img, read_exr(dir / "inverse.exr"));
    HS_TRY(check_map_image(dir / "inverse.exr", img, m.device_width, m.device_height));
    const size_t n = size_t(img.width) * img.height;
    m.x.resize(n), m.y.resize(n), m.valid.resize(n);
    for (size_t i = 0; i < n; ++i) {
        const float x = img.pixels[i * 4], y = img.pixels[i * 4 + 1];
        m.valid[i] = img.pixels[i * 4 + 2] > 0.5f && std::isfinite(x) && std::isfinite(y);
        m.x[i] = m.valid[i] ? x : NAN;
        m.y[i] = m.valid[i] ? y : NAN;
        m.estimated += m.valid[i];
    }
    return m;
}

Result<void> save_colour(const fs::path& file, const ColourCalibration& c) {
    json matrix = json::array(), response = json::array();
    for (int p = 0; p < 3; ++p) matrix.push_back({c.matrix[p][0], c.matrix[p][1], c.matrix[p][2]});
    for (const auto& r : c.response) {
        json knots = json::array();
        for (const auto& [d, v] : r) knots.push_back({d, v});
        response.push_back(knots);
    }
    return write_json(file, {{"kind", "hysar-colour"},
                             {"model", to_string(c.model)},
                             {"primaries", matrix},
                             {"offset", {c.offset.r, c.offset.g, c.offset.b}},
                             {"response", response},
                             {"condition", c.condition},
                             {"rmse_dn_per_s", c.rmse},
                             {"mean_de00", c.mean_de00},
                             {"max_de00", c.max_de00},
                             {"samples", c.samples}});
}

Result<ColourCalibration> load_colour(const fs::path& file) {
    return from_json<ColourCalibration>(
        file, "hysar-colour", [&](const json& j) -> Result<ColourCalibration> {
            ColourCalibration c;
            const json& model = field(j, "model", "model");
            if (!model.is_string())
                throw FieldError("model is not \"linear\" or \"curve\"");
            auto parsed = parse_colour_model(model.get<std::string>());
            if (!parsed)
                throw FieldError("model: " + parsed.error().message);
            c.model = parsed.value();
            const json& primaries = array_of(j, "primaries", 3, "primaries");
            for (int p = 0; p < 3; ++p) {
                const json& row = primaries.at(p);
                if (!row.is_array() || row.size() != 3)
                    throw FieldError(fmt::format("primaries[{}] is not an array of 3", p));
                for (int k = 0; k < 3; ++k)
                    c.matrix[p][k] =
                        finite_number(row.at(k), fmt::format("primaries[{}][{}]", p, k));
            }
            const json& offset = array_of(j, "offset", 3, "offset");
            for (int k = 0; k < 3; ++k)
                c.offset[k] = finite_number(offset.at(k), fmt::format("offset[{}]", k));
            if (c.model == ColourModel::kCurve) {
                const json& response = array_of(j, "response", 3, "response");
                for (int ch = 0; ch < 3; ++ch) {
                    const json& knots = response.at(ch);
                    if (!knots.is_array() || knots.size() < 2)
                        throw FieldError(fmt::format("response[{}] has fewer than 2 knots", ch));
                    for (size_t i = 0; i < knots.size(); ++i) {
                        const std::string name = fmt::format("response[{}][{}]", ch, i);
                        if (!knots[i].is_array() || knots[i].size() != 2)
                            throw FieldError(name + " is not a (drive, response) pair");
                        const double d = finite_number(knots[i][0], name + "[0]");
                        const double v = finite_number(knots[i][1], name + "[1]");
                        if (d < 0 || d > 1 || (i > 0 && !(d > c.response[ch].back().first)) ||
                            (i > 0 && v < c.response[ch].back().second))
                            throw FieldError(fmt::format(
                                "{} = ({}, {}): knots must rise in drive within [0, 1] and "
                                "never fall in response",
                                name, d, v));
                        c.response[ch].push_back({d, v});
                    }
                }
            }
            c.condition = j.value("condition", 0.0);
            c.rmse = j.value("rmse_dn_per_s", 0.0);
            c.mean_de00 = j.value("mean_de00", 0.0);
            c.max_de00 = j.value("max_de00", 0.0);
            c.samples = j.value("samples", uint64_t(0));
            if (!(std::fabs(glm::determinant(c.matrix)) > 1e-12))
                return make_error(ErrorCode::kParse,
                                  fmt::format("{}: the primaries are degenerate", file.string()));
            return c;
        });
}

Result<void> save_optics(const fs::path& file, const OpticalConstants& c) {
    const auto& l = c.levels;
    json j = {
        {"kind", "hysar-optics"},
        {"comment",
         "Optical constants of the installation (docs/CALIBRATION.md, optics.json): the "
         "headset's transparency alpha, the scene-to-signal scale k (0: per scene, the "
         "largest the projector can show), the device levels and room light in camera DN/s "
         "(docs/OPTICS.md), the prop's albedo; projectors: the levels of each projector whose "
         "own differ"},
        {"source", c.source},
        {"alpha", c.alpha},
        {"scene_to_signal", c.scene_to_signal},
        {"levels",
         {{"projector_max", l.projector_max},
          {"projector_min", l.projector_min},
          {"hmd_max", l.hmd_max},
          {"hmd_min", l.hmd_min},
          {"environment", l.environment}}},
        {"prop_albedo", {c.prop_albedo.r, c.prop_albedo.g, c.prop_albedo.b}}};
    if (!c.projector_levels.empty()) {
        json each = json::object();
        for (const auto& [name, lv] : c.projector_levels)
            each[name] = {{"projector_max", lv.max}, {"projector_min", lv.min}};
        j["projectors"] = std::move(each);
    }
    return write_json(file, j);
}

scene::DeviceLevels OpticalConstants::levels_of(const std::string& name) const {
    scene::DeviceLevels l = levels;
    if (auto it = projector_levels.find(name); it != projector_levels.end()) {
        l.projector_max = it->second.max;
        l.projector_min = it->second.min;
    }
    return l;
}

namespace {

// A device level (camera DN/s) at `key` of `j`, named `at`.key in errors: finite and >= 0.
double level_of(const json& j, const char* key, const std::string& at) {
    const std::string name = at + "." + key;
    const double v = finite_number(j, key, name);
    if (v < 0)
        throw FieldError(fmt::format("{} is {} DN/s; levels are >= 0", name, v));
    return v;
}

}  // namespace

Result<OpticalConstants> load_optics(const fs::path& file) {
    return from_json<OpticalConstants>(file, "hysar-optics", [](const json& j) {
        OpticalConstants c;
        c.source = j.value("source", std::string());
        c.alpha = finite_number(j, "alpha", "alpha");
        if (!(c.alpha > 0 && c.alpha <= 1))
            throw FieldError(fmt::format("alpha is {}, outside (0, 1]", c.alpha));
        c.scene_to_signal = finite_number(j, "scene_to_signal", "scene_to_signal");
        if (c.scene_to_signal < 0)
            throw FieldError(fmt::format("scene_to_signal is {}; it must be >= 0 (0: per scene)",
                                         c.scene_to_signal));
        const json& l = field(j, "levels", "levels");
        auto level = [&](const char* key) { return level_of(l, key, "levels"); };
        c.levels.projector_max = level("projector_max");
        c.levels.projector_min = level("projector_min");
        c.levels.hmd_max = level("hmd_max");
        c.levels.hmd_min = level("hmd_min");
        c.levels.environment = level("environment");
        if (!(c.levels.projector_max > c.levels.projector_min))
            throw FieldError(
                fmt::format("levels.projector_max ({}) must be above levels.projector_min ({})",
                            c.levels.projector_max, c.levels.projector_min));
        if (!(c.levels.hmd_max > c.levels.hmd_min))
            throw FieldError(fmt::format("levels.hmd_max ({}) must be above levels.hmd_min ({})",
                                         c.levels.hmd_max, c.levels.hmd_min));
        if (j.contains("projectors")) {
            const json& each = j.at("projectors");
            if (!each.is_object())
                throw FieldError("projectors is not an object of projector names to their levels");
            for (const auto& [name, lj] : each.items()) {
                const std::string at = "projectors." + name;
                if (!lj.is_object())
                    throw FieldError(fmt::format("{} is not an object", at));
                OpticalConstants::ProjectorLevels pl{level_of(lj, "projector_max", at),
                                                     level_of(lj, "projector_min", at)};
                if (!(pl.max > pl.min))
                    throw FieldError(
                        fmt::format("{0}.projector_max ({1}) must be above "
                                    "{0}.projector_min ({2})",
                                    at, pl.max, pl.min));
                c.projector_levels[name] = pl;
            }
        }
        const json& albedo = array_of(j, "prop_albedo", 3, "prop_albedo");
        for (int k = 0; k < 3; ++k) {
            const std::string name = fmt::format("prop_albedo[{}]", k);
            c.prop_albedo[k] = finite_number(albedo.at(k), name);
            if (!(c.prop_albedo[k] > 0 && c.prop_albedo[k] <= 10))
                throw FieldError(fmt::format("{} is {}, outside (0, 10]", name, c.prop_albedo[k]));
        }
        return c;
    });
}

Result<void> save_device_directory(const fs::path& dir, const DeviceLut& lut,
                                   const DecodeOptions& decode, const DeviceCalibration& cal) {
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec)
        return make_error(ErrorCode::kIo, fmt::format("{}: cannot create the folder: {}",
                                                      dir.string(), ec.message()));
    HS_TRY(save_lut(dir, lut, decode));
    HS_TRY(write_png(dir / "lut.png", lut_picture(lut)));
    HS_TRY(write_exr(dir / "white.exr", cal.white));
    HS_TRY(write_exr(dir / "black.exr", cal.black));
    HS_TRY(save_inverse(dir, cal.inverse));
    return save_colour(dir / "colour.json", cal.colour);
}

Result<DeviceCalibration> load_device_calibration(const fs::path& dir) {
    DeviceCalibration d;
    HS_ASSIGN_OR_RETURN(d.inverse, load_inverse(dir));
    HS_ASSIGN_OR_RETURN(d.colour, load_colour(dir / "colour.json"));
    HS_ASSIGN_OR_RETURN(d.white, read_exr(dir / "white.exr"));
    HS_ASSIGN_OR_RETURN(d.black, read_exr(dir / "black.exr"));
    return d;
}

Result<ImageRgba32f> read_camera_image(const fs::path& file) {
    const std::string ext = file.extension().string();
    if (ext == ".exr")
        return read_exr(file);
    if (ext != ".png")
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("{}: camera images are .exr (DN) or 8-bit .png", file.string()));
    HS_ASSIGN_OR_RETURN(ImageRgba8 png, read_png(file));
    ImageRgba32f out = ImageRgba32f::zeros(png.width, png.height);
    for (size_t i = 0; i < png.pixels.size(); ++i)
        out.pixels[i] = (i % 4 == 3) ? 1.0f : float(png.pixels[i]);
    return out;
}

}  // namespace hs::calib
