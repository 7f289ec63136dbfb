// One viewer's frame on its way from the scheduler to the socket (docs/ARCHITECTURE.md, "One VD
// layer, thread by thread"). Each registered viewer owns one, made at its first frame and
// re-made only when its display changes: two render targets in the layer's own pixel format,
// whose persistently mapped readback buffers the encoder reads in place. The render thread
// fills it and submits; the encoder waits for its timeline value, encodes and hands the bytes
// on; the scheduler gives the viewer no new frame until then, so one frame is never written
// and read at once.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

#include "codec/layer_codec.hpp"
#include "gpu/resources.hpp"
#include "render/renderer.hpp"
#include "stream/scheduler.hpp"

namespace hs::stream {

struct ViewerFrame {
    uint32_t viewer = 0;
    uint32_t width = 0, height = 0;
    protocol::PixelFormat format = protocol::PixelFormat::kRgba8;
    std::array<gpu::RenderTarget, 2> targets;  // per eye, in the layer's pixel format
    std::array<gpu::Buffer, 2> indices;        // per eye, the drawn clusters' indices
    uint64_t target_bytes = 0;                 // what the two targets hold
    uint64_t index_bytes = 0;                  // what the two index buffers hold

    // Per frame, written by the render thread before the frame goes to the encoder.
    ViewerJob job;
    std::array<codec::LayerPixels, 2> pixels;  // what each eye's layer is made of
    std::array<render::Renderer::LayerPlan, 2> plans;
    uint64_t timeline = 0;  // the submission whose completion makes `pixels` valid; 0: none
    std::chrono::steady_clock::time_point taken, submitted;
    // Keeps the pixels a captured material's frame points at alive while it is encoded.
    std::shared_ptr<const void> keep_alive;
};

}  // namespace hs::stream
