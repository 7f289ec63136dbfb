// A projector at 1/div of its resolution (its focal lengths scaled with it, the principal point
// at the centre), for the tests that render or blend several projectors quickly.
#pragma once

#include <cstdint>

#include "scene/scene.hpp"

namespace hs::test {

inline void shrink(scene::Projector& p, uint32_t div) {
    auto& k = p.intrinsics;
    k = {k.width / div,
         k.height / div,
         k.fx / div,
         k.fy / div,
         (k.width / div - 1) * 0.5,
         (k.height / div - 1) * 0.5};
}

}  // namespace hs::test
