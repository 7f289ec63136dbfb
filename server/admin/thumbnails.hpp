// Thumbnails of what the server sent: a VdLayer or ProjectorFrame, as it went to the socket,
// decoded, box-filtered down and encoded as PNG, only when the admin endpoint is asked, and
// cached so that however many dashboards ask, a picture is made at most once per frame and at
// most once per kThumbnailMinInterval.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
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

// A cached thumbnail is served, even when a newer frame exists, until it is this old: headsets
// run at 60-90 Hz, so without it nearly every ask would decode and encode a new PNG. At most
// 1 s / 250 ms = 4 PNGs per second per picture, whatever the number of dashboards open.
inline constexpr std::chrono::milliseconds kThumbnailMinInterval{250};
// An entry nobody asked for in this long (a departed viewer's, a closed dashboard's) is dropped
// by the next ask of any picture.
inline constexpr std::chrono::seconds kThumbnailUnusedExpiry{10};

// The pixels of one encoded VdLayer or ProjectorFrame (a whole frame: header and payload), as
// 8-bit sRGB with full alpha, scaled down (box filter in linear light) so that its longer side
// is at most `max_side`. An error names what did not decode.
Result<ImageRgba8> frame_thumbnail(const std::vector<uint8_t>& frame, uint32_t max_side);

// PNG bytes of `image`.
Result<std::string> thumbnail_png(const ImageRgba8& image);

// PNGs per (viewer, eye) and of the projector frame, each keyed by the frame it was made from:
// one entry per picture, replaced when its frame changes (at most once per `min_interval`),
// dropped when its viewer leaves (retain(), forget()) or when nobody asked for it in
// kThumbnailUnusedExpiry. Thread: any (one lock, not held while decoding or encoding).
class ThumbnailCache {
public:
    using Clock = std::chrono::steady_clock;
    using Now = std::function<Clock::time_point()>;
    // `now` is the clock (a test's own, so that nothing depends on timing).
    explicit ThumbnailCache(uint32_t max_side, Clock::duration min_interval = kThumbnailMinInterval,
                            Now now = Clock::now)
        : max_side_(max_side), min_interval_(min_interval), now_(std::move(now)) {}
    // The PNG for `key` of `latest` (a frame and the sequence naming it; not null): the cached
    // one while it was made from that frame or is younger than min_interval, else made anew
    // (one ask makes it; asks meanwhile get the previous PNG).
    Result<std::shared_ptr<const std::string>> get(const std::string& key,
                                                   const stream::LatestFrame& latest);
    // Drops the entries whose key is not in `keep`.
    void retain(const std::vector<std::string>& keep);
    // Drops `key`'s entry (its picture is gone).
    void forget(const std::string& key);
    uint64_t bytes() const;    // PNG bytes held
    uint64_t encoded() const;  // PNGs made since start
    size_t entries() const;    // pictures held

private:
    struct Entry {
        uint64_t sequence = 0;
        std::shared_ptr<const std::string> png;
        Clock::time_point made, asked;
    };
    const uint32_t max_side_;
    const Clock::duration min_interval_;
    const Now now_;
    mutable std::mutex mutex_;
    std::map<std::string, Entry> entries_;
    uint64_t encoded_ = 0;
};

}  // namespace hs::admin
