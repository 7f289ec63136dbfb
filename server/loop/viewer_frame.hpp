// One viewer's frame on its way from the scheduler to the socket (docs/ARCHITECTURE.md, "One VD
// layer, thread by thread"). Each registered viewer owns one, made at its first frame and
// re-made only when its display changes: two render targets in the layer's own pixel format,
// whose persistently mapped readback buffers the encoder reads in place. The render thread
// fills it and submits; the encoder waits for its timeline value, encodes and hands the bytes
// on; the scheduler gives the viewer no new frame until then, so one frame is never written
// and read at once.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "gpu/resources.hpp"
#include "loop/viewer.hpp"
#include "render/renderer.hpp"

namespace hs::loop {

// One eye's layer where its pixels lie (a persistently mapped readback buffer, or a captured
// image): rows `stride` bytes apart, in `encoding`; only the rectangle [x0, x1) x [y0, y1) is
// read, the rest of the layer is black, and of it only `parts` where there are several (the
// rest of the rectangle is black too, and its memory not the layer's). Or, from a target that
// packs its tiles, the lit tiles the device packed (codec::LayerPixels::tile_info; `data`
// null).
struct EyePixels {
    const uint8_t* data = nullptr;
    size_t stride = 0;  // bytes
    uint32_t width = 0, height = 0;
    render::LayerEncoding encoding = render::LayerEncoding::kSrgb8;
    uint32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
    const uint32_t* tile_info = nullptr;
    const uint8_t* tiles = nullptr;
    render::RectParts parts;  // count <= 1: the whole rectangle
};

// One submission's figures (stats "frames"): its viewers' eyes, the time from taking the
// batch to submitting it (culling and recording), whether it was a large display's own turn,
// and the source's report of its pass.
struct BatchFigures {
    uint64_t eyes = 0;
    double queue_ms = 0;
    // Of queue_ms: planning and recording the layers (the fill), and the rest of the
    // submission: waiting for a free command buffer, beginning, ending and submitting it.
    double record_ms = 0, submit_ms = 0;
    bool large_turn = false;
    nlohmann::json report;
};

// A layer target headsets of one batch share (render::Renderer::pass_headsets): headset i's
// eyes are its views 2i and 2i + 1, all drawn in one pass. The frame loop keeps these in a pool;
// each frame drawn into one holds it until the encoder has read its pixels
// (ViewerFrame::let_go_of_shared), and the frame loop draws into it again only once none does.
struct SharedTarget {
    gpu::RenderTarget target;
    std::atomic<uint32_t> holders{0};  // frames that still read it
    uint64_t bytes = 0;                // what it holds
    Clock::time_point last_used;       // render thread
};

struct ViewerFrame {
    uint32_t viewer = 0;
    uint32_t width = 0, height = 0;
    render::LayerEncoding encoding = render::LayerEncoding::kSrgb8;
    // Per eye, in the layer's pixel format; or both eyes in targets[0], a target of two views
    // (render::Renderer::multiview), and targets[1] empty.
    std::array<gpu::RenderTarget, 2> targets;
    std::array<gpu::Buffer, 2> indices;  // per eye, the drawn clusters' indices
    uint64_t target_bytes = 0;           // what the two targets hold
    uint64_t index_bytes = 0;            // what the two index buffers hold
    // What its own two targets hold or, sharing, would hold: the pool of shared targets is
    // kept within twice the sum of these (the server reserves as much per display).
    uint64_t own_target_bytes = 0;

    // Per frame, written by the render thread before the frame goes to the encoder.
    ViewerJob job;
    std::array<EyePixels, 2> pixels;  // what each eye's layer is made of
    std::array<render::Renderer::LayerPlan, 2> plans;
    bool one_pass = false;  // both eyes were drawn by one multiview pass
    // Or both eyes in views first_view and first_view + 1 of a target shared with other
    // headsets of the batch, from when the render thread takes the frame until the encoder has
    // read it; then the frame's own targets are not made.
    SharedTarget* shared = nullptr;
    uint32_t first_view = 0;
    uint32_t pass_headsets = 0;  // headsets whose eyes the frame's pass drew (0: no pass)
    uint64_t timeline = 0;       // the submission whose completion makes `pixels` valid; 0: none
    std::chrono::steady_clock::time_point taken, submitted;
    // Keeps the pixels a captured material's frame points at alive while it is encoded.
    std::shared_ptr<const void> keep_alive;
    // What the batch it was rendered in did, carried to the stats on the frame of the batch
    // that comes first (null on the others): the frame loop writes no stats of its own.
    std::shared_ptr<const BatchFigures> batch;

    // Eye e's target and view in it.
    gpu::RenderTarget& eye_target(size_t e) {
        return shared ? shared->target : targets[targets[0].views() > 1 ? 0 : e];
    }
    uint32_t eye_view(size_t e) const {
        return shared ? first_view + uint32_t(e) : targets[0].views() > 1 ? uint32_t(e) : 0;
    }
    // Done with the shared target (its pixels read, or the frame given up): the frame loop may
    // draw into it again once every frame in it has let go. Thread: whoever holds the frame.
    void let_go_of_shared() {
        if (shared)
            shared->holders.fetch_sub(1, std::memory_order_release);
        shared = nullptr;
    }
};

}  // namespace hs::loop
