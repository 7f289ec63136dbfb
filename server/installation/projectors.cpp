#include "installation/projectors.hpp"

#include <chrono>
#include <cmath>
#include <optional>

#include <fmt/format.h>

#include "core/check.hpp"

namespace hs::installation {

namespace {

// Where camera pixel i's calibrated device pixel really lands, as a camera-pixel offset from
// i: J^-1 (lut - truth), J the true map's Jacobian by central (or one-sided) differences.
std::optional<std::pair<double, double>> landing_offset(const calib::DeviceLut& lut,
                                                        const std::vector<float>& tx,
                                                        const std::vector<float>& ty, uint32_t x,
                                                        uint32_t y) {
    const uint32_t w = lut.camera_width, h = lut.camera_height;
    const size_t i = size_t(y) * w + x;
    auto finite = [&](size_t k) { return std::isfinite(tx[k]) && std::isfinite(ty[k]); };
    if (!finite(i))
        return std::nullopt;
    // d(truth)/dx and d(truth)/dy, each from the neighbours that have a true map.
    auto diff = [&](bool along_x, double& dtx, double& dty) {
        const bool has_lo = along_x ? x > 0 : y > 0;
        const bool has_hi = along_x ? x + 1 < w : y + 1 < h;
        const size_t lo = along_x ? i - 1 : i - w, hi = along_x ? i + 1 : i + w;
        const bool lo_ok = has_lo && finite(lo), hi_ok = has_hi && finite(hi);
        if (lo_ok && hi_ok) {
            dtx = (tx[hi] - tx[lo]) / 2.0;
            dty = (ty[hi] - ty[lo]) / 2.0;
        } else if (hi_ok) {
            dtx = tx[hi] - tx[i];
            dty = ty[hi] - ty[i];
        } else if (lo_ok) {
            dtx = tx[i] - tx[lo];
            dty = ty[i] - ty[lo];
        } else {
            return false;
        }
        return true;
    };
    double a, c, b, d;  // J = [[a, b], [c, d]]: columns d/dx and d/dy
    if (!diff(true, a, c) || !diff(false, b, d))
        return std::nullopt;
    const double det = a * d - b * c;
    if (!(std::abs(det) > 1e-9))
        return std::nullopt;
    const double ex = double(lut.x[i]) - tx[i], ey = double(lut.y[i]) - ty[i];
    return std::pair{(d * ex - b * ey) / det, (-c * ex + a * ey) / det};
}

}  // namespace

scene::Scene single_projector_scene(const scene::Scene& s, size_t index) {
    scene::Scene one = s;
    one.projector = s.projectors().at(index);
    one.more_projectors.clear();
    // Its own levels, where the scene gives them (as render::blended_projector_drive).
    one.optics.levels.projector_max =
        one.projector.white_level.value_or(s.optics.levels.projector_max);
    one.optics.levels.projector_min =
        one.projector.black_level.value_or(s.optics.levels.projector_min);
    return one;
}

scene::Scene installed_scene(std::span<const std::unique_ptr<VirtualInstallation>> installations) {
    HS_CHECK(!installations.empty(), "installed_scene: no installation");
    scene::Scene s = installations.front()->scene();
    s.more_projectors.clear();
    for (size_t j = 1; j < installations.size(); ++j)
        s.more_projectors.push_back(installations[j]->scene().projector);
    return s;
}

Result<ImageRgba32f> capture_together(
    std::span<const std::unique_ptr<VirtualInstallation>> installations,
    std::span<const ImageRgba32f> drives, uint64_t seed) {
    if (installations.empty() || drives.size() != installations.size())
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("capture_together: {} drive image(s) for {} projector(s)",
                                      drives.size(), installations.size()));
    // sum_j (alpha (P_j + E) + H) - (K - 1) (alpha E + H): each signal is linear in the light.
    HS_ASSIGN_OR_RETURN(ImageRgba32f sum, installations[0]->signal(drives[0], {}));
    HS_ASSIGN_OR_RETURN(const ImageRgba32f base, installations[0]->signal({}, {}, false));
    for (size_t j = 1; j < installations.size(); ++j) {
        HS_ASSIGN_OR_RETURN(const ImageRgba32f s, installations[j]->signal(drives[j], {}));
        if (s.width != sum.width || s.height != sum.height)
            return make_error(ErrorCode::kInvalidArgument,
                              "capture_together: the installations' cameras differ in size");
        for (size_t i = 0; i < sum.pixels.size(); ++i)
            if (i % 4 != 3)
                sum.pixels[i] += s.pixels[i] - base.pixels[i];
    }
    return installations[0]->expose(sum, seed);
}

MapError pair_registration(const calib::DeviceLut& a, const std::vector<float>& ax,
                           const std::vector<float>& ay, const calib::DeviceLut& b,
                           const std::vector<float>& bx, const std::vector<float>& by) {
    std::vector<double> d;
    uint64_t untrue = 0;
    const uint32_t w = a.camera_width, h = a.camera_height;
    const size_t n = size_t(w) * h;
    for (const auto* v : {&ax, &ay, &bx, &by, &a.x, &a.y, &b.x, &b.y})
        if (v->size() != n)
            return map_error({}, 0);
    if (b.camera_width != w || b.camera_height != h || a.state.size() != n || b.state.size() != n)
        return map_error({}, 0);
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
            const size_t i = size_t(y) * w + x;
            if (!a.is_valid(i) || !b.is_valid(i))
                continue;
            const auto oa = landing_offset(a, ax, ay, x, y);
            const auto ob = landing_offset(b, bx, by, x, y);
            if (!oa || !ob) {
                ++untrue;
                continue;
            }
            d.push_back(std::hypot(oa->first - ob->first, oa->second - ob->second));
        }
    return map_error(std::move(d), untrue);
}

Result<ProjectorsReport> calibrate_projectors(gpu::Device& device, const scene::Scene& s,
                                              const Options& io, const ChainOptions& co,
                                              const Log& log) {
    ProjectorsReport rep;
    struct Truth {
        std::vector<float> x, y;
    };
    std::vector<Truth> truths;
    const auto all = s.projectors();
    for (size_t j = 0; j < all.size(); ++j) {
        const auto t0 = std::chrono::steady_clock::now();
        const std::string& name = all[j].name;
        HS_ASSIGN_OR_RETURN(auto inst,
                            VirtualInstallation::create(device, single_projector_scene(s, j), io));
        const Log tagged = [&](const std::string& line) {
            if (log)
                log(fmt::format("projector '{}' ({}/{}): {}", name, j + 1, all.size(), line));
        };
        HS_ASSIGN_OR_RETURN(DeviceResult r,
                            calibrate_device(*inst, Device::kProjector, co, tagged));
        truths.push_back({inst->truth_x(Device::kProjector), inst->truth_y(Device::kProjector)});
        rep.projectors.push_back(
            {name, std::move(r),
             std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()});
        rep.installations.push_back(std::move(inst));
    }
    for (size_t j = 0; j < all.size(); ++j)
        for (size_t k = j + 1; k < all.size(); ++k) {
            const auto& pj = rep.projectors[j].result.lut;
            const auto& pk = rep.projectors[k].result.lut;
            ProjectorPair p{
                all[j].name, all[k].name,
                pair_registration(pj, truths[j].x, truths[j].y, pk, truths[k].x, truths[k].y)};
            if (log)
                log(
                    fmt::format("projectors '{}' and '{}': {} camera pixels lit by both; "
                                "registration median {:.3f} px, p95 {:.3f} px (camera pixels)",
                                p.a, p.b, p.error.pixels, p.error.median_px, p.error.p95_px));
            rep.pairs.push_back(std::move(p));
        }
    return rep;
}

}  // namespace hs::installation
