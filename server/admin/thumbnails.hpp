// Thumbnails of what the server sent: a VdLayer or ProjectorFrame, as it went to the socket,
// decoded, box-filtered down and encoded as PNG, only when the admin endpoint is asked, and
// cached per frame so that repeated asks cost nothing.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <tuple>
#include <vector>

#include "core/image.hpp"
#include "core/result.hpp"
#include "stream/snapshot.hpp"

namespace hs::admin {

// The pixels of one encoded VdLayer or ProjectorFrame (a whole frame: header and payload), as
// 8-bit sRGB with full alpha, scaled down (box filter in linear light) so that its longer side
// is at most `max_side`. An error names what did not decode.
Result<ImageRgba8> frame_thumbnail(const std::vector<uint8_t>& frame, uint32_t max_side);

// PNG bytes of `image`.
Result<std::string> thumbnail_png(const ImageRgba8& image);

// PNGs per (viewer, eye) and of the projector frame, each keyed by the frame it was made from:
// one entry per picture, replaced when its frame changes, dropped when its viewer leaves.
// Thread: any (one lock, not held while decoding or encoding).
class ThumbnailCache {
public:
    explicit ThumbnailCache(uint32_t max_side) : max_side_(max_side) {}
    // The PNG of `frame` (sequence `sequence`) for `key`, made once per sequence.
    Result<std::shared_ptr<const std::string>> get(const std::string& key, uint64_t sequence,
                                                   const stream::Bytes& frame);
    // Drops the entries whose key is not in `keep`.
    void retain(const std::vector<std::string>& keep);
    uint64_t bytes() const;    // PNG bytes held
    uint64_t encoded() const;  // PNGs made since start

private:
    struct Entry {
        uint64_t sequence = 0;
        std::shared_ptr<const std::string> png;
    };
    const uint32_t max_side_;
    mutable std::mutex mutex_;
    std::map<std::string, Entry> entries_;
    uint64_t encoded_ = 0;
};

}  // namespace hs::admin
