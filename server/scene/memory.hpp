// The bytes a scene holds on the CPU, and its heavy parts charged to a SceneLedger counter for
// as long as any copy of the scene shares them (core/memory_ledger.hpp).
#pragma once

#include <cstdint>

#include "core/memory_ledger.hpp"
#include "scene/scene.hpp"

namespace hs::scene {

// Bytes of a mesh's arrays (their capacity).
uint64_t mesh_bytes(const Mesh& mesh);

// Bytes of the data a scene shares between its copies: the glTF prop's mesh, the albedo
// texture and a captured material's images (the rest of a Scene is a few kilobytes).
uint64_t shared_data_bytes(const Scene& scene);

// Makes each of the scene's shared parts count on `counter` (null: no change) until the last
// copy of the scene, or of the part, is gone: the part is re-pointed through a holder that
// carries its charge, so every copy made from `scene` afterwards shares the charge.
void charge_shared_data(Scene& scene, MemoryCounter* counter);

}  // namespace hs::scene
