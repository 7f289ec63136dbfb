// What accuracy costs in time (docs/ACCURACY.md): every quality knob of the VD layer swept
// against the double-precision reference, with its error and its cost measured in one process.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "core/image.hpp"
#include "core/result.hpp"
#include "gpu/device.hpp"
#include "plot/figure.hpp"
#include "scene/scene.hpp"

namespace hs::bench {

struct AccuracyOptions {
    bool quick = false;  // a quarter of the headset's resolution, fewer settings and repeats
    int repeats = 7;     // timed renders per setting (after one untimed warm-up)
    std::function<void(const std::string&)> progress;  // one line per step, may be empty
};

// One setting of one knob. Errors are of the VD layer against the reference of what the knob
// approximates (`reference`); costs are medians over the repeats. The motion rows (knob
// "motion", one per mode of `hysar bench motion` on a short head turn) have an error and a cost
// of their own: the highlight's registration error at photon time (p95_px) and the client's
// time per stereo frame (client_ms); their layer fields (rmse to bytes) are not measured.
struct AccuracyRow {
    std::string knob;     // tessellation, render-scale, samples-per-pixel, lights, format,
                          // encoding, format+encoding, motion
    std::string setting;  // e.g. "128x32", "0.5", "4 spp", "area K=16", "rgba16f", "f16 tiles+lz4"
    std::string reference;  // centre: exact at pixel centres; box: the pixel-area integral;
                            // area: the converged area-light integral at pixel centres
    bool is_default = false;
    double geometric_error_mm = -1;  // tessellation: largest distance of the mesh from the
                                     // exact hemisphere; -1 elsewhere
    double rmse = 0;                 // linear radiance, over pixels either image covers, RGB
    double mean_de00 = 0;  // CIEDE2000 over the VD area (reference visible in an RGBA8 layer),
                           // radiance 1 = display white
    double render_ms = 0;  // one layer: record, submit, wait, readback (and the box filter of
                           // supersampling; a reduced scale's upsampling is the headset's)
    double encode_ms = 0;  // pixel conversion and layer encoding in the row's (or default) encoding
    double bytes = 0;      // encoded layer
    double p95_px = -1;    // motion: the highlight's error against a fresh render for the
                           // true pose at photon time, p95, the profile's pixels; -1 elsewhere
    double p50_px = -1;    // motion: the same, p50
    double client_ms = -1;  // motion: prediction and reprojection per stereo frame, CPU time of
                            // one core (mean); -1 elsewhere
    bool pareto = false;    // no other setting of this knob is both cheaper and more accurate
    bool is_motion() const { return p95_px >= 0; }
    // What the row costs and what error it leaves, in the knob's own units: render + encode ms
    // and RMSE, or for motion rows client ms per stereo frame and p95 pixels.
    double cost_ms() const { return is_motion() ? client_ms : render_ms + encode_ms; }
    double error() const { return is_motion() ? p95_px : rmse; }
};

struct AccuracyReport {
    std::vector<AccuracyRow> rows;
    std::string device;
    uint32_t width = 0, height = 0;  // the VD layer
    int repeats = 0;
    double seconds = 0;  // wall time of the whole run
};

Result<AccuracyReport> run_accuracy(gpu::Device& device, const scene::Scene& scene,
                                    const AccuracyOptions& options);

// The median of `v` (the mean of the middle two for an even count; 0 when empty).
double median(std::vector<double> v);

// Marks, per knob, the settings no other setting of the same knob dominates in
// (cost_ms(), error()).
void mark_pareto(std::vector<AccuracyRow>& rows);

// Largest distance (mm) of the tessellated hemisphere's triangles from the exact surface,
// sampled on a barycentric grid over every triangle.
double hemisphere_geometric_error_mm(const scene::Hemisphere& hemisphere);

std::string accuracy_csv(const AccuracyReport& report);
std::string accuracy_table(const AccuracyReport& report);
Figure accuracy_plot(const AccuracyReport& report);

}  // namespace hs::bench
