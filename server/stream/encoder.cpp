#include "stream/encoder.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>

#include "codec/layer_codec.hpp"
#include "protocol/tiles.hpp"

namespace hs::stream {

namespace {
double ms_between(std::chrono::steady_clock::time_point a,
                  std::chrono::steady_clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
}

static_assert(loop::kLayerTile == protocol::kDefaultTileSize,
              "the frame loop grows rendered rectangles to the wire's tile grid");

// The wire's warp depth: whole micrometres, at least 1 (0 says none); a depth past 10 km is
// sent as 10 km (a plane that far is a rotation).
uint64_t warp_depth_um(double depth_m) {
    if (!(depth_m > 0))
        return 0;
    return uint64_t(std::clamp(std::llround(std::min(depth_m, 1e4) * 1e6), 1LL, 10'000'000'000LL));
}

static_assert(codec::kMaxLayerParts == render::kMaxLayerParts);

codec::LayerPixels wire_pixels(const loop::EyePixels& p) {
    codec::LayerPixels out{p.data, p.stride, p.width, p.height, wire_format(p.encoding),
                           p.x0,   p.y0,     p.x1,    p.y1,     p.tile_info,
                           p.tiles};
    out.part_count = p.parts.count;
    for (uint32_t i = 0; i < p.parts.count; ++i) {
        const auto& r = p.parts.parts[i];
        out.parts[i] = {r.x0, r.y0, r.x1, r.y1};
    }
    return out;
}

// The bytes of a layer's pixels the host reads: its rectangle, or the lit tiles the device
// packed with their count and mask.
uint64_t read_back_bytes(const codec::LayerPixels& p) {
    const uint64_t bpp = p.format == protocol::PixelFormat::kRgba8 ? 4 : 8;
    if (p.tile_info) {
        const uint64_t ts = protocol::kDefaultTileSize;
        const uint64_t tiles = ((p.width + ts - 1) / ts) * ((p.height + ts - 1) / ts);
        return p.tile_info[0] * ts * ts * bpp + 16 + (tiles + 31) / 32 * 4;
    }
    std::array<codec::LayerPart, codec::kMaxLayerParts> areas;
    uint64_t pixels = 0;
    for (size_t i = 0, n = p.read_areas(areas); i < n; ++i)
        pixels += uint64_t(areas[i].x1 - areas[i].x0) * (areas[i].y1 - areas[i].y0);
    return pixels * bpp;
}

// The headset drive over tiles the device packed: each tile's pixels inside the layer through
// the drive, its padding past the layer's edge left zero, into `dst` (the same packing).
void drive_packed(const calib::LayerDrive& drive, const codec::LayerPixels& px, uint8_t* dst) {
    const uint32_t ts = protocol::kDefaultTileSize;
    const bool rgba8 = px.format == protocol::PixelFormat::kRgba8;
    const size_t stride = size_t(ts) * (rgba8 ? 4 : 8), tile_bytes = stride * ts;
    const uint32_t tx = (px.width + ts - 1) / ts, ty = (px.height + ts - 1) / ts;
    const uint32_t count = px.tile_info[0];
    const uint32_t* mask = px.tile_info + 4;
    uint32_t k = 0;
    for (uint32_t t = 0; t < tx * ty && k < count; ++t) {
        if (!(mask[t / 32] >> (t % 32) & 1u))
            continue;
        const uint32_t cw = std::min(ts, px.width - t % tx * ts),
                       ch = std::min(ts, px.height - t / tx * ts);
        if (cw < ts || ch < ts)
            std::memset(dst + size_t(k) * tile_bytes, 0, tile_bytes);
        if (rgba8)
            drive.apply_rgba8(px.tiles, stride, dst, stride, 0, k * ts, cw, k * ts + ch);
        else
            drive.apply_rgba16f(px.tiles, stride, dst, stride, 0, k * ts, cw, k * ts + ch);
        ++k;
    }
}
}  // namespace

protocol::PixelFormat wire_format(render::LayerEncoding encoding) {
    return encoding == render::LayerEncoding::kSrgb8 ? protocol::PixelFormat::kRgba8
                                                     : protocol::PixelFormat::kRgba16f;
}

protocol::Encoding wire_encoding(loop::LayerPacking packing) {
    switch (packing) {
        case loop::LayerPacking::kRaw:
            return protocol::Encoding::kRaw;
        case loop::LayerPacking::kSparseTiles:
            return protocol::Encoding::kSparseTiles;
        case loop::LayerPacking::kLossyTiles:
            return protocol::Encoding::kLossyTiles;
    }
    return protocol::Encoding::kSparseTiles;
}

std::vector<uint8_t> BufferPool::take() {
    std::lock_guard lock(mutex_);
    if (free_.empty())
        return {};
    std::vector<uint8_t> v = std::move(free_.back());
    free_.pop_back();
    pooled_bytes_ -= v.capacity();
    return v;
}

Bytes BufferPool::share(std::vector<uint8_t>&& filled) {
    auto* v = new std::vector<uint8_t>(std::move(filled));
    std::weak_ptr<BufferPool> pool = weak_from_this();
    return Bytes(v, [pool](const std::vector<uint8_t>* p) {
        auto* owned = const_cast<std::vector<uint8_t>*>(p);
        if (auto alive = pool.lock())
            alive->give_back(std::move(*owned));
        delete owned;
    });
}

void BufferPool::give_back(std::vector<uint8_t>&& v) {
    std::lock_guard lock(mutex_);
    if (free_.size() >= kMaxPooled)
        return;
    pooled_bytes_ += v.capacity();
    free_.push_back(std::move(v));
}

uint64_t BufferPool::pooled_bytes() const {
    std::lock_guard lock(mutex_);
    return pooled_bytes_;
}

Encoder::Encoder(const gpu::SubmitRing& ring, std::shared_ptr<BufferPool> pool, uint32_t threads,
                 std::optional<protocol::TileCodec> codec, Done done, int layer_quality)
    : ring_(ring),
      pool_(std::move(pool)),
      codec_(codec),
      quality_(std::clamp(layer_quality, 1, 100)),
      done_(std::move(done)) {
    for (uint32_t i = 0; i < std::max<uint32_t>(threads, 1); ++i)
        threads_.emplace_back([this] { run(); });
}

Encoder::~Encoder() {
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
    }
    cv_.notify_all();
    for (auto& t : threads_) t.join();
}

void Encoder::push(std::shared_ptr<loop::ViewerFrame> frame) {
    {
        std::lock_guard lock(mutex_);
        queue_.push_back(std::move(frame));
    }
    cv_.notify_one();
}

void Encoder::drain() {
    std::unique_lock lock(mutex_);
    idle_.wait(lock, [&] { return queue_.empty() && busy_ == 0; });
}

void Encoder::set_layer_drive(std::shared_ptr<const calib::LayerDrive> drive) {
    std::lock_guard lock(mutex_);
    drive_ = std::move(drive);
}

void Encoder::run() {
    LayerScratch scratch;  // reused by this thread
    for (;;) {
        std::shared_ptr<loop::ViewerFrame> frame;
        std::shared_ptr<const calib::LayerDrive> drive;
        {
            std::unique_lock lock(mutex_);
            cv_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
            if (queue_.empty())
                return;  // stopping, and nothing left
            frame = std::move(queue_.front());
            queue_.pop_front();
            drive = drive_;
            ++busy_;
        }
        EncodedFrame out = encode(std::move(frame), drive.get(), scratch);
        try {
            done_(std::move(out));
        } catch (...) {
            // done_ counts and posts; a failure there must not take the thread down.
        }
        {
            std::lock_guard lock(mutex_);
            --busy_;
        }
        idle_.notify_all();
    }
}

void append_served_layer(std::vector<uint8_t>& out, const codec::LayerPixels& pixels,
                         const calib::LayerDrive* drive, protocol::Encoding encoding,
                         protocol::TileCodec codec, LayerScratch& scratch, int quality) {
    const uint32_t x1 = std::min(pixels.x1, pixels.width), y1 = std::min(pixels.y1, pixels.height);
    if (!drive || pixels.x0 >= x1 || pixels.y0 >= y1) {
        codec::append_layer_data(out, pixels, encoding, codec, scratch.tiles, quality);
        return;
    }
    if (pixels.tile_info) {  // only the packed tiles through the drive
        const uint32_t ts = protocol::kDefaultTileSize;
        const size_t bytes = size_t(pixels.tile_info[0]) * ts * ts *
                             (pixels.format == protocol::PixelFormat::kRgba8 ? 4 : 8);
        if (scratch.driven_bytes < bytes) {
            scratch.driven.reset(new uint8_t[bytes]);
            scratch.driven_bytes = bytes;
        }
        drive_packed(*drive, pixels, scratch.driven.get());
        codec::LayerPixels driven = pixels;
        driven.tiles = scratch.driven.get();
        codec::append_layer_data(out, driven, encoding, codec, scratch.tiles, quality);
        return;
    }
    // The rectangle through the headset drive, at the same place in a layer-sized buffer, so
    // that the tile packer reads it as it would the mapped readback.
    const bool rgba8 = pixels.format == protocol::PixelFormat::kRgba8;
    const size_t stride = size_t(pixels.width) * (rgba8 ? 4 : 8);
    const size_t bytes = stride * pixels.height;
    if (scratch.driven_bytes < bytes) {
        scratch.driven.reset(new uint8_t[bytes]);  // not zeroed: only what is written is read
        scratch.driven_bytes = bytes;
    }
    // The tile packer reads whole tiles: the drive covers the rectangle (or each of its parts)
    // rounded out to the tile grid, so that no byte of the buffer it reads is left unwritten.
    uint8_t* dst = scratch.driven.get();
    std::array<codec::LayerPart, codec::kMaxLayerParts> areas;
    for (size_t i = 0, n = pixels.read_areas(areas); i < n; ++i) {
        const codec::LayerPart& a = areas[i];
        const render::PixelRect t = render::align_to_tiles(
            {a.x0, a.y0, a.x1, a.y1}, protocol::kDefaultTileSize, pixels.width, pixels.height);
        if (rgba8)
            drive->apply_rgba8(pixels.data, pixels.stride, dst, stride, t.x0, t.y0, t.x1, t.y1);
        else
            drive->apply_rgba16f(pixels.data, pixels.stride, dst, stride, t.x0, t.y0, t.x1, t.y1);
    }
    codec::LayerPixels driven = pixels;
    driven.data = dst;
    driven.stride = stride;
    codec::append_layer_data(out, driven, encoding, codec, scratch.tiles, quality);
}

EncodedFrame Encoder::encode(std::shared_ptr<loop::ViewerFrame> frame,
                             const calib::LayerDrive* drive, LayerScratch& scratch) {
    const loop::ViewerFrame& f = *frame;
    // A target shared with other headsets' frames is theirs again once this one is read.
    struct LetGo {
        loop::ViewerFrame& f;
        ~LetGo() { f.let_go_of_shared(); }
    } let_go{*frame};
    EncodedFrame out;
    out.viewer = f.viewer;
    out.pose_received = f.job.pose.received;
    out.plans = f.plans;
    out.batch = f.batch;
    auto t0 = std::chrono::steady_clock::now();
    if (f.timeline != 0) {
        if (auto r = ring_.wait(f.timeline); !r.ok()) {
            out.error = r.error().message;
            return out;
        }
        t0 = std::chrono::steady_clock::now();
        out.gpu_ms = ms_between(f.submitted, t0);
        out.device_ms = ring_.device_ms(f.timeline);
    }
    if (encode_layers(f, drive, scratch, out))
        out.encode_ms = ms_between(t0, std::chrono::steady_clock::now());
    return out;  // the frame is let go here, on this thread
}

bool Encoder::encode_layers(const loop::ViewerFrame& f, const calib::LayerDrive* drive,
                            LayerScratch& scratch, EncodedFrame& out) {
    const protocol::PixelFormat format = wire_format(f.encoding);
    const protocol::Encoding encoding = wire_encoding(f.job.display.packing);
    // Lossy tiles: sRGB8 layers through codec 3 at the server's quality (RGBA16F ones go
    // lossless, which encoding 3 allows); the lossless encodings never see codec 3.
    const protocol::TileCodec codec =
        encoding == protocol::Encoding::kLossyTiles && format == protocol::PixelFormat::kRgba8
            ? protocol::TileCodec::kJpeg
            : codec_.value_or(codec::default_tile_codec(format));
    // The viewer's bit-rate limit may lower its quality (loop/bit_rate.hpp); 0: the server's.
    const int quality =
        f.job.layer_quality > 0 ? std::clamp(f.job.layer_quality, 1, 100) : quality_;
    out.one_pass = f.one_pass;
    out.pass_headsets = f.pass_headsets;
    for (uint8_t e = 0; e < 2; ++e) {
        protocol::VdLayer fields;
        fields.frame_id = f.job.frame_id;
        fields.pose_time_ns = f.job.pose.client_time_ns;
        fields.display_time_ns = f.job.pose.display_time_ns;
        if (f.job.display.warp_depth)
            fields.warp_depth_um = warp_depth_um(f.plans[e].warp_depth_m);
        fields.eye = e;
        fields.format = format;
        fields.encoding = encoding;
        fields.width = f.width;
        fields.height = f.height;
        const codec::LayerPixels pixels = wire_pixels(f.pixels[e]);
        out.read_back_bytes += read_back_bytes(pixels);
        std::vector<uint8_t> buf = pool_->take();
        auto err = protocol::encode_vd_layer_into(buf, fields, 0, [&](std::vector<uint8_t>& o) {
            append_served_layer(o, pixels, drive, encoding, codec, scratch, quality);
            return true;
        });
        if (err) {
            out.error = err->message;
            return false;
        }
        out.layers[e] = pool_->share(std::move(buf));
    }
    return true;
}

}  // namespace hs::stream
