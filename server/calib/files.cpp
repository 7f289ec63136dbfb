#include "calib/files.hpp"

#include <cmath>
#include <fstream>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

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

// Runs `fn` on a parsed file; a missing key or wrong type becomes an error naming the file.
template <typename T, typename Fn>
Result<T> from_json(const fs::path& file, const char* kind, Fn fn) {
    HS_ASSIGN_OR_RETURN(json j, read_json(file));
    try {
        if (j.value("kind", std::string()) != kind)
            return make_error(ErrorCode::kParse,
                              fmt::format("{}: not a {} file (its \"kind\" is not \"{}\")",
                                          file.string(), kind, kind));
        return fn(j);
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
    HS_ASSIGN_OR_RETURN(
        DeviceLut lut,
        (from_json<DeviceLut>(dir / "lut.json", "hysar-lut", [](const json& j) -> DeviceLut {
            DeviceLut l;
            l.camera_width = j.at("camera").at(0);
            l.camera_height = j.at("camera").at(1);
            l.device_width = j.at("device").at(0);
            l.device_height = j.at("device").at(1);
            return l;
        })));
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
            HS_ASSIGN_OR_RETURN(c.model, parse_colour_model(j.at("model")));
            for (int p = 0; p < 3; ++p)
                for (int k = 0; k < 3; ++k) c.matrix[p][k] = j.at("primaries").at(p).at(k);
            for (int k = 0; k < 3; ++k) c.offset[k] = j.at("offset").at(k);
            if (c.model == ColourModel::kCurve)
                for (int ch = 0; ch < 3; ++ch) {
                    for (const auto& k : j.at("response").at(ch))
                        c.response[ch].push_back({k.at(0), k.at(1)});
                    if (c.response[ch].size() < 2)
                        return make_error(ErrorCode::kParse,
                                          fmt::format("{}: response curve {} has fewer than 2 "
                                                      "knots",
                                                      file.string(), ch));
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
