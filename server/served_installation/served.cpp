#include "served_installation/served.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <fmt/format.h>

#include "clients/net/connection.hpp"
#include "codec/layer_codec.hpp"
#include "optics/capture.hpp"
#include "protocol/tiles.hpp"
#include "scene/camera.hpp"
#include "stream/loopback.hpp"

namespace hs::installation {

namespace {

namespace proto = hs::protocol;
using Clock = std::chrono::steady_clock;

// The drives a client's panel receives from a frame's or a layer's bytes: each channel's code
// (RGBA8), or the sRGB encoding of the half float (RGBA16F), as codec::drive_from_layer.
Result<ImageRgba32f> received_drive(const std::vector<uint8_t>& data, uint32_t w, uint32_t h,
                                    proto::PixelFormat format, proto::Encoding encoding) {
    const uint32_t bpp = format == proto::PixelFormat::kRgba8 ? 4 : 8;
    std::vector<uint8_t> raw;
    if (encoding != proto::Encoding::kRaw) {
        auto d = proto::decode_tiles(data, w, h, bpp);
        if (auto* e = std::get_if<std::string>(&d))
            return make_error(ErrorCode::kParse, "served layer: " + *e);
        raw = std::move(std::get<std::vector<uint8_t>>(d));
    } else {
        raw = data;
    }
    ImageRgba32f px = codec::decode_pixels(raw, w, h, format);
    if (px.empty())
        return make_error(ErrorCode::kParse,
                          fmt::format("served image: {} bytes for {}x{}", raw.size(), w, h));
    return codec::drive_from_layer(px);
}

// Waits for a message of type T on `c`; an Error from the server, a closed connection or the
// time running out is an error.
template <typename T>
Result<T> await(client::Connection& c, int timeout_ms, const char* what) {
    const auto deadline = Clock::now() + std::chrono::milliseconds(timeout_ms);
    while (Clock::now() < deadline) {
        auto r = c.receive(500);
        if (auto* e = std::get_if<std::string>(&r))
            return make_error(ErrorCode::kIo, fmt::format("waiting for {}: {}", what, *e));
        if (auto* m = std::get_if<proto::Message>(&r)) {
            if (auto* t = std::get_if<T>(m))
                return std::move(*t);
            if (auto* err = std::get_if<proto::Error>(m))
                return make_error(ErrorCode::kInvalidArgument,
                                  fmt::format("waiting for {}: the server answered {}", what,
                                              client::describe(*err)));
        }
    }
    return make_error(ErrorCode::kIo, fmt::format("no {} within {} ms", what, timeout_ms));
}

struct Received {
    ImageRgba32f projector, hmd;
};

Result<Received> receive_served(const std::string& address, const std::string& token,
                                const VirtualInstallation& inst, const ServeOptions& o) {
    auto open = [&]() -> Result<std::unique_ptr<client::Connection>> {
        auto c = client::Connection::open(address);
        if (auto* e = std::get_if<std::string>(&c))
            return make_error(ErrorCode::kIo, *e);
        return std::move(std::get<std::unique_ptr<client::Connection>>(c));
    };
    Received out;
    HS_ASSIGN_OR_RETURN(auto projector, open());
    if (auto e = projector->hello(proto::Role::kProjector, token, "virtual-projector"))
        return make_error(ErrorCode::kIo, "projector hello: " + *e);
    HS_ASSIGN_OR_RETURN(
        proto::ProjectorFrame pf,
        await<proto::ProjectorFrame>(*projector, o.timeout_ms, "the projector frame"));
    HS_ASSIGN_OR_RETURN(out.projector,
                        received_drive(pf.data, pf.width, pf.height, pf.format, pf.encoding));

    HS_ASSIGN_OR_RETURN(auto hmd, open());
    if (auto e = hmd->hello(proto::Role::kHmd, token, "virtual-headset"))
        return make_error(ErrorCode::kIo, "headset hello: " + *e);
    // The camera is the eye: the installation's display, the camera's pose, no IPD.
    const scene::Intrinsics& k = inst.viewpoint().intrinsics;
    proto::RegisterDisplay d{k.width, k.height, k.fx,     k.fy,       k.cx,
                             k.cy,    0.0,      o.format, o.encoding, proto::FrameMode::kOnRequest};
    const scene::Pose& head = inst.viewpoint().camera;
    const glm::dquat q = head.orientation;
    proto::Pose pose{1, {head.position.x, head.position.y, head.position.z}, {q.w, q.x, q.y, q.z}};
    if (!hmd->send(d) || !hmd->send(pose) || !hmd->send(proto::FrameRequest{}))
        return make_error(ErrorCode::kIo, "headset: " + hmd->last_error());
    for (;;) {
        HS_ASSIGN_OR_RETURN(proto::VdLayer l,
                            await<proto::VdLayer>(*hmd, o.timeout_ms, "the headset's VD layer"));
        if (l.eye != 0)
            continue;  // both eyes are the camera's view; the left one is shown
        HS_ASSIGN_OR_RETURN(out.hmd,
                            received_drive(l.data, l.width, l.height, l.format, l.encoding));
        break;
    }
    return out;
}

}  // namespace

calib::OpticalConstants optical_constants(const VirtualInstallation& inst) {
    const scene::Optics& o = inst.scene().optics;
    calib::OpticalConstants c;
    c.alpha = inst.alpha();
    c.scene_to_signal = inst.scene_to_signal();
    c.levels = optics::effective_levels(o);
    c.prop_albedo = o.effects.prop_albedo ? o.prop_albedo : glm::dvec3(1.0);
    c.source = fmt::format(
        "virtual installation (hysar calibrate simulate, scale {}): its devices' levels, its "
        "prop's albedo, its headset's alpha and the k of its reference",
        inst.options().scale);
    return c;
}

Result<void> save_calibration(const std::filesystem::path& dir, const VirtualInstallation& inst,
                              const DeviceResult& projector, const DeviceResult& hmd,
                              const ChainOptions& options, const ProjectorsReport* several) {
    calib::OpticalConstants c = optical_constants(inst);
    if (several) {
        for (size_t j = 0; j < several->projectors.size(); ++j) {
            const ProjectorCalibration& p = several->projectors[j];
            HS_TRY(calib::save_device_directory(dir / "projectors" / p.name, p.result.lut,
                                                options.decode, p.result.calibration));
            if (j < several->installations.size()) {
                const auto l = optics::effective_levels(several->installations[j]->scene().optics);
                c.projector_levels[p.name] = {l.projector_max, l.projector_min};
            }
        }
    } else {
        HS_TRY(calib::save_device_directory(dir / "projector", projector.lut, options.decode,
                                            projector.calibration));
    }
    HS_TRY(calib::save_device_directory(dir / "hmd", hmd.lut, options.decode, hmd.calibration));
    return calib::save_optics(dir / "optics.json", c);
}

Result<ServedCapture> serve_and_capture(
    gpu::Device& device, const VirtualInstallation& inst,
    std::shared_ptr<const calib::ServingCalibration> calibration, const ServeOptions& o) {
    stream::LoopbackCreateInfo info;
    info.token = "virtual-installation";
    info.calibration = std::move(calibration);
    HS_ASSIGN_OR_RETURN(auto server, stream::LoopbackServer::start(device, inst.scene(), info));
    auto got = receive_served(server->address(), server->token(), inst, o);
    server->stop();
    if (!got)
        return got.error();

    ServedCapture out;
    out.projector = std::move(got->projector);
    out.hmd = std::move(got->hmd);
    const auto reference = inst.reference(o.seed);
    out.reference = reference.vi_vd;
    HS_ASSIGN_OR_RETURN(out.capture, inst.capture(out.projector, out.hmd, o.seed + 101));
    const ImageRgba8 ref8 = optics::to_rgba8(out.reference);
    const ImageRgba8 cap8 = optics::to_rgba8(out.capture);
    HS_ASSIGN_OR_RETURN(out.areas, optics::vd_areas(ref8, optics::to_rgba8(reference.vi), cap8));
    const auto& lit = inst.truth_x(Device::kProjector);
    std::vector<uint8_t> prop(lit.size());
    double se = 0;
    for (size_t i = 0; i < lit.size(); ++i) {
        prop[i] = !std::isnan(lit[i]);
        if (!prop[i])
            continue;
        ++out.prop_pixels;
        for (int c = 0; c < 3; ++c) {
            const double d =
                double(out.capture.pixels[i * 4 + c]) - out.reference.pixels[i * 4 + c];
            se += d * d;
        }
    }
    out.rmse_dn = out.prop_pixels ? std::sqrt(se / (3.0 * double(out.prop_pixels))) : 0.0;
    const ImageRgba8 again8 = optics::to_rgba8(inst.reference(o.seed + 202).vi_vd);
    auto mean_de00 = [&](const ImageRgba8& img, const std::vector<uint8_t>& mask) {
        auto lab = optics::lab_differences(ref8, img, mask, optics::PixelEncoding::kLinear);
        return lab.ok() ? lab->s00.mean : NAN;  // the sizes agree by construction
    };
    out.prop_mean_de00 = mean_de00(cap8, prop);
    out.noise_prop_mean_de00 = mean_de00(again8, prop);
    out.vd_pixels = out.areas.reference_count;
    if (out.vd_pixels) {
        out.vd_mean_de00 = mean_de00(cap8, out.areas.reference);
        out.noise_vd_mean_de00 = mean_de00(again8, out.areas.reference);
    }
    return out;
}

Result<BlendCapture> serve_blend_and_capture(
    gpu::Device& device, const ProjectorsReport& several,
    std::shared_ptr<const calib::ServingCalibration> calibration, const ServeOptions& o) {
    const auto& insts = several.installations;
    if (insts.size() < 2)
        return make_error(ErrorCode::kInvalidArgument,
                          "the blend on the simulated capture needs two or more projectors");
    const scene::Scene room = installed_scene(insts);
    stream::LoopbackCreateInfo info;
    info.token = "virtual-installation";
    info.clients = uint32_t(insts.size()) + 1;
    info.calibration = std::move(calibration);
    HS_ASSIGN_OR_RETURN(auto server, stream::LoopbackServer::start(device, room, info));
    // A projector client per projector, by name: each receives its own frame.
    BlendCapture out;
    std::vector<ImageRgba32f> drives;
    for (const auto& pj : room.projectors()) {
        auto c = client::Connection::open(server->address());
        if (auto* e = std::get_if<std::string>(&c))
            return make_error(ErrorCode::kIo, *e);
        auto& conn = *std::get<std::unique_ptr<client::Connection>>(c);
        if (auto e = conn.hello(proto::Role::kProjector, server->token(), pj.name))
            return make_error(ErrorCode::kIo, fmt::format("projector '{}' hello: {}", pj.name, *e));
        HS_ASSIGN_OR_RETURN(
            proto::ProjectorFrame pf,
            await<proto::ProjectorFrame>(conn, o.timeout_ms, "a projector's frame"));
        HS_ASSIGN_OR_RETURN(ImageRgba32f d,
                            received_drive(pf.data, pf.width, pf.height, pf.format, pf.encoding));
        drives.push_back(std::move(d));
        out.names.push_back(pj.name);
    }
    server->stop();

    const VirtualInstallation& first = *insts.front();
    out.reference = first.reference(o.seed).vi;
    HS_ASSIGN_OR_RETURN(out.capture, capture_together(insts, drives, o.seed + 101));
    // Camera pixels of the prop by how many projectors light them.
    const size_t n = out.reference.pixels.size() / 4;
    std::vector<uint8_t> single(n, 0), overlap(n, 0);
    for (size_t i = 0; i < n; ++i) {
        int lit = 0;
        for (const auto& inst : insts) lit += !std::isnan(inst->truth_x(Device::kProjector)[i]);
        single[i] = lit == 1;
        overlap[i] = lit >= 2;
        out.single_pixels += single[i];
        out.overlap_pixels += overlap[i];
    }
    const ImageRgba8 ref8 = optics::to_rgba8(out.reference), cap8 = optics::to_rgba8(out.capture);
    const ImageRgba8 again8 = optics::to_rgba8(first.reference(o.seed + 202).vi);
    auto de00 = [&](const ImageRgba8& img, const std::vector<uint8_t>& mask,
                    double* p95) -> double {
        auto lab = optics::lab_differences(ref8, img, mask, optics::PixelEncoding::kLinear);
        if (!lab.ok())
            return NAN;
        if (p95 && !lab->de00.empty()) {
            std::vector<double> v = lab->de00;
            const size_t k = size_t(0.95 * double(v.size() - 1));
            std::nth_element(v.begin(), v.begin() + k, v.end());
            *p95 = v[k];
        }
        return lab->s00.mean;
    };
    // The capture's luminance over the reference's, sorted, over `mask` (where the reference
    // is above a DN).
    auto ratios = [&](const std::vector<uint8_t>& mask) {
        auto luminance = [](const float* p) {
            return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
        };
        std::vector<double> ratio;
        for (size_t i = 0; i < n; ++i) {
            const double r = luminance(&out.reference.pixels[i * 4]);
            if (mask[i] && r > 1.0)
                ratio.push_back(luminance(&out.capture.pixels[i * 4]) / r);
        }
        std::sort(ratio.begin(), ratio.end());
        return ratio;
    };
    auto at = [](const std::vector<double>& v, double q) {
        return v.empty() ? 0.0 : v[size_t(q * double(v.size() - 1))];
    };
    if (out.single_pixels) {
        out.single_mean_de00 = de00(cap8, single, nullptr);
        out.single_luminance_ratio = at(ratios(single), 0.5);
    }
    if (out.overlap_pixels) {
        out.overlap_mean_de00 = de00(cap8, overlap, &out.overlap_p95_de00);
        out.noise_overlap_mean_de00 = de00(again8, overlap, nullptr);
        const std::vector<double> r = ratios(overlap);
        out.overlap_luminance_ratio = at(r, 0.5);
        out.overlap_ratio_p05 = at(r, 0.05);
        out.overlap_ratio_p95 = at(r, 0.95);
    }
    return out;
}

}  // namespace hs::installation
