// A serving calibration made in memory, for tests that serve calibrated layers without running
// the calibration chain.
#pragma once

#include "calib/serving.hpp"
#include "scene/config.hpp"

namespace hs::test {

// A calibration of the test scene's own sizes, made in memory: a linear device of 1000 DN/s.
inline calib::ServingCalibration synthetic(const scene::Scene& s, uint32_t hmd_w, uint32_t hmd_h) {
    calib::ServingCalibration c;
    c.dir = "synthetic";
    c.projector.dir = "synthetic/projector";
    c.projector.width = s.projector.intrinsics.width;
    c.projector.height = s.projector.intrinsics.height;
    c.hmd.dir = "synthetic/hmd";
    c.hmd.width = hmd_w;
    c.hmd.height = hmd_h;
    for (auto* d : {&c.projector, &c.hmd}) {
        d->colour.model = calib::ColourModel::kLinear;
        d->colour.matrix = glm::dmat3(1000.0);
        d->colour.offset = glm::dvec3(20.0);
    }
    c.optics.alpha = 0.4;
    return c;
}

}  // namespace hs::test
