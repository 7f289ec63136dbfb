#include "core/check.hpp"
#include "scene/config.hpp"

namespace hs::scene {

Scene default_scene() {
    auto s = parse_scene(default_scene_json(), "<embedded default scene>", ".");
    HS_CHECK(s.ok(), "the embedded default scene must parse");
    return std::move(s).value();
}

}  // namespace hs::scene
