// The hard-case table (docs/STABILITY.md): every specular model and every formula with a hard
// regime, run through the GPU's own shading code (render::run_shading_probe) and compared case by
// case with the double-precision reference, each regime with its tolerance stated in absolute
// and relative terms. The GPU tests assert it (tests/gpu/stability_test.cpp) and
// `hysar bench stability` prints it with the errors in ulps.
#pragma once

#include <string>
#include <vector>

#include <glm/mat3x3.hpp>

#include "core/result.hpp"
#include "gpu/device.hpp"
#include "render/probe.hpp"
#include "scene/scene.hpp"

namespace hs::bench {

struct StabilityRegime {
    std::string formula;  // "phong", "ward", "lambert", "point light", "half layer", ...
    std::string regime;   // "grazing light, n.l -> 0+"
    scene::Specular spec;
    std::vector<render::ProbeCase> cases;  // as the GPU receives them (fp32-rounded)
    // A case passes when, for the diffuse and the specular radiance alike,
    //   fp32:       |GPU - ref| <= rel |ref| + abs + s
    //   half layer: |GPU - min(ref, 65504)| <= (rel + 2^-11) |ref| + abs + 2^-25 + s
    // where s is how far the reference moves when l or v turns by 2^-23 rad (the fp32 rounding
    // of a cosine: it matters only where a term divides by a cosine near 0, Ward at grazing),
    // and neither is NaN, Inf or negative, nor does the half layer hold 65504 where the reference
    // is below it. With non_finite_input the reference is undefined: the fp32 value may be
    // anything, the half layer must be finite, non-negative and at most 65504.
    double rel = 2e-3, abs = 1e-6;
    bool non_finite_input = false;
};

struct StabilityRow {
    std::string formula, regime;
    double rel = 0, abs = 0;
    bool non_finite_input = false;
    size_t cases = 0, failures = 0;
    double max_abs_error = 0;  // fp32, over every case
    double max_rel_error = 0;  // fp32, over cases whose reference exceeds abs
    double max_ulps = 0;       // fp32 ulps of the reference, over the same cases
    double half_max_rel_error = 0, half_max_ulps = 0;  // the half layer, same cases (ref < 65504)
    double peak_reference = 0;                         // largest reference radiance in the regime
    std::string first_failure;                         // empty when every case passed
};

// The table. Ward below alpha 1e-4 is in it only where the device has shaderFloat64 (without it
// the shaders take the fp32 fallback, docs/SHADING.md).
std::vector<StabilityRegime> stability_regimes(bool float64);

// Runs every regime on `device`; an Error only where the probe itself cannot run.
Result<std::vector<StabilityRow>> run_stability(gpu::Device& device,
                                                const std::vector<StabilityRegime>& regimes);

// A readable table (fixed-width text; markdown when `markdown`) and a CSV of the rows.
std::string stability_table(const std::vector<StabilityRow>& rows, bool markdown);
std::string stability_csv(const std::vector<StabilityRow>& rows);

// The blend of several projectors in its hard cases (docs/STABILITY.md, "Several projectors"):
// a point one projector sees at grazing incidence, points no projector sees, two projectors at
// identical poses, a projector whose frame misses the prop, a prop that shadows part of itself.
// CPU only (render/blend.hpp). Each case's projectors are small (a few hundred pixels a side).
struct BlendCaseRow {
    std::string name;
    size_t projectors = 0;
    uint64_t points = 0;                  // surface points sampled (prop pixels of every projector)
    uint64_t covered = 0;                 // of which at least one projector reaches
    double max_weight_sum_error = 0;      // max |sum_j w_j - 1| over covered points
    double max_uncovered_weight = 0;      // max sum_j w_j over points no projector reaches
    bool finite = true;                   // every weight and every drive finite
    double min_drive = 0, max_drive = 0;  // over every projector's drive (must lie in [0, 1])
    std::string check;                    // the case's own check, "" when it held, else why
    bool ok() const;
};
std::vector<BlendCaseRow> run_blend_hard_cases();
std::string blend_cases_table(const std::vector<BlendCaseRow>& rows);

// Helpers shared with the probe tests: a rotation taking +z to a direction near no axis (fixed
// seeds: reproducible), and a case's vectors and scalars rounded to what the GPU receives, so
// that a reference computed from them measures the shader's own arithmetic.
glm::dmat3 tilted_frame(uint32_t seed);
render::ProbeCase as_gpu_inputs(const render::ProbeCase& c);

}  // namespace hs::bench
