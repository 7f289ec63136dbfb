// The encoder threads, the door on the way out: each takes a submitted ViewerFrame (the frame
// loop's FrameSink), waits for its timeline value (the GPU finished writing its readback
// buffers), encodes both eyes' layers from the mapped memory in place into one buffer per layer
// (header and payload together, sent as they are: the only code besides the session that knows
// the wire format), lets go of the frame and hands the layers on. Buffers come from a pool and go
// back to it when the socket is done with them, so a steady stream allocates nothing large. A
// calibrated server's layers go through the headset drive's lookups first (calib::LayerDrive), into
// memory the thread keeps.
#pragma once

#include <condition_variable>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "calib/serving.hpp"
#include "codec/layer_codec.hpp"
#include "gpu/submit_ring.hpp"
#include "loop/frame_loop.hpp"
#include "loop/viewer_frame.hpp"

namespace hs::stream {

using Bytes = std::shared_ptr<const std::vector<uint8_t>>;

// Byte buffers reused from frame to frame. Thread: any.
class BufferPool : public std::enable_shared_from_this<BufferPool> {
public:
    // A buffer (empty, with the capacity of an earlier frame's when there is one).
    std::vector<uint8_t> take();
    // Shares a filled buffer; it returns to the pool when its last user lets go.
    Bytes share(std::vector<uint8_t>&& filled);
    // Capacity of the buffers resting in the pool.
    uint64_t pooled_bytes() const;

private:
    void give_back(std::vector<uint8_t>&& v);
    static constexpr size_t kMaxPooled = 256;
    mutable std::mutex mutex_;
    std::vector<std::vector<uint8_t>> free_;
    uint64_t pooled_bytes_ = 0;
};

// What one encoder thread keeps between layers: the packed tiles, and the driven pixels of a
// calibrated layer (allocated once, at the largest layer's size; only the rendered rectangle
// is written and read).
struct LayerScratch {
    std::vector<uint8_t> tiles;
    std::unique_ptr<uint8_t[]> driven;
    size_t driven_bytes = 0;
};

// One eye's layer data as the encoder appends it to `out` (after the message's fields):
// `pixels` in `encoding` (codec 3 at `quality`, 1..100), through `drive` first when the server is
// calibrated (the headset drive of the rendered rectangle, into scratch.driven); `drive` null: the
// pixels as rendered, at the cost of one pointer test. Thread: the caller's, with its own scratch.
void append_served_layer(std::vector<uint8_t>& out, const codec::LayerPixels& pixels,
                         const calib::LayerDrive* drive, protocol::Encoding encoding,
                         protocol::TileCodec codec, LayerScratch& scratch,
                         int quality = protocol::kDefaultLayerQuality);

// The wire's pixel format and layer encoding of loop's domain values (the door's conversions
// on the way out; session.cpp has the way in).
protocol::PixelFormat wire_format(render::LayerEncoding encoding);
protocol::Encoding wire_encoding(loop::LayerPacking packing);

// One encoded frame: both eyes' wire frames, or why there are none, with what the frame loop
// and the encoder measured on the way (the frame itself is let go before it is handed on).
struct EncodedFrame {
    uint32_t viewer = 0;
    std::chrono::steady_clock::time_point pose_received;
    std::array<render::Renderer::LayerPlan, 2> plans;
    std::shared_ptr<const loop::BatchFigures> batch;  // the frame that came first in its batch
    std::array<Bytes, 2> layers;
    std::string error;  // non-empty: nothing to send
    double gpu_ms = 0;  // submitted -> the GPU finished (as the encoder saw it)
    // The device's own time on the frame's submission (timestamps); unset where not known.
    std::optional<double> device_ms;
    double encode_ms = 0;  // both layers, CPU
    // What the encoder read of the two layers' pixels, as the device left them for the host:
    // the rectangles, or (packed on the device) the lit tiles with the count and the mask.
    uint64_t read_back_bytes = 0;
    bool one_pass = false;       // both eyes were rendered in one multiview pass
    uint32_t pass_headsets = 0;  // headsets whose eyes that pass drew (several: a shared one)
};

// Owns its queue (under its lock: the render thread pushes, its threads take) and its threads.
class Encoder final : public loop::FrameSink {
public:
    using Done = std::function<void(EncodedFrame&&)>;
    // `threads` encoder threads; `done` is called on them, once per pushed frame, after the
    // frame was let go: it hands the result on (a post) and returns. `layer_quality`: codec 3's
    // quality (1..100) for the layers of headsets that asked for lossy tiles.
    Encoder(const gpu::SubmitRing& ring, std::shared_ptr<BufferPool> pool, uint32_t threads,
            std::optional<protocol::TileCodec> codec, Done done,
            int layer_quality = protocol::kDefaultLayerQuality);
    ~Encoder() override;  // encodes what is queued, then joins
    Encoder(const Encoder&) = delete;
    Encoder& operator=(const Encoder&) = delete;

    // Render thread.
    void push(std::shared_ptr<loop::ViewerFrame> frame) override;
    // Blocks until every pushed frame was handed to `done`.
    void drain() override;
    // The headset drive of the frames pushed from now on (null: none). The render thread sets
    // it with each scene version, after drain().
    void set_layer_drive(std::shared_ptr<const calib::LayerDrive> drive) override;

private:
    void run();
    EncodedFrame encode(std::shared_ptr<loop::ViewerFrame> frame, const calib::LayerDrive* drive,
                        LayerScratch& scratch);
    // The two layers of `f` into `out.layers`; false (out.error set) when one cannot be.
    bool encode_layers(const loop::ViewerFrame& f, const calib::LayerDrive* drive,
                       LayerScratch& scratch, EncodedFrame& out);

    const gpu::SubmitRing& ring_;
    std::shared_ptr<BufferPool> pool_;
    std::optional<protocol::TileCodec> codec_;
    int quality_;
    Done done_;
    std::mutex mutex_;
    std::condition_variable cv_, idle_;
    std::deque<std::shared_ptr<loop::ViewerFrame>> queue_;
    std::shared_ptr<const calib::LayerDrive> drive_;  // under mutex_
    size_t busy_ = 0;
    bool stopping_ = false;
    std::vector<std::thread> threads_;
};

}  // namespace hs::stream
