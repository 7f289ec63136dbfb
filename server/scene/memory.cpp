#include "scene/memory.hpp"

#include <memory>

namespace hs::scene {

namespace {

uint64_t image_bytes(const ImageRgba8& i) {
    return i.pixels.capacity();
}
uint64_t image_bytes(const ImageRgba32f& i) {
    return i.pixels.capacity() * sizeof(float);
}

// `part` re-pointed through a holder that keeps the original and its charge alive: the charge
// goes when the last pointer to the holder does.
template <typename T>
void charge(std::shared_ptr<const T>& part, MemoryCounter* counter, uint64_t bytes) {
    if (!part)
        return;
    struct Holder {
        std::shared_ptr<const T> part;
        MemoryCharge charge;
    };
    auto holder = std::make_shared<Holder>(Holder{part, MemoryCharge(counter, int64_t(bytes))});
    const T* raw = part.get();
    part = std::shared_ptr<const T>(std::move(holder), raw);
}

}  // namespace

uint64_t mesh_bytes(const Mesh& m) {
    return m.positions.capacity() * sizeof(m.positions[0]) +
           m.normals.capacity() * sizeof(m.normals[0]) + m.uvs.capacity() * sizeof(m.uvs[0]) +
           m.tangents.capacity() * sizeof(m.tangents[0]) +
           m.indices.capacity() * sizeof(m.indices[0]);
}

uint64_t shared_data_bytes(const Scene& s) {
    uint64_t n = 0;
    if (s.prop.gltf_mesh)
        n += mesh_bytes(*s.prop.gltf_mesh);
    if (s.material.albedo_texture)
        n += image_bytes(*s.material.albedo_texture);
    if (s.captured_material) {
        if (s.captured_material->projector_image)
            n += image_bytes(*s.captured_material->projector_image);
        if (s.captured_material->viewer_image)
            n += image_bytes(*s.captured_material->viewer_image);
    }
    return n;
}

void charge_shared_data(Scene& s, MemoryCounter* counter) {
    if (!counter)
        return;
    if (s.prop.gltf_mesh)
        charge(s.prop.gltf_mesh, counter, mesh_bytes(*s.prop.gltf_mesh));
    if (s.material.albedo_texture)
        charge(s.material.albedo_texture, counter, image_bytes(*s.material.albedo_texture));
    if (auto& c = s.captured_material) {
        if (c->projector_image)
            charge(c->projector_image, counter, image_bytes(*c->projector_image));
        if (c->viewer_image)
            charge(c->viewer_image, counter, image_bytes(*c->viewer_image));
    }
}

}  // namespace hs::scene
