// libFuzzer target: any bytes given to the decoder, as sent by a client and as sent by the
// server, give a message or a DecodeError, never a crash, a sanitizer report or an unbounded
// allocation; a message that decodes is one encode() accepts, and it re-encodes to the same
// bytes. The UTF-8 functions keep their contracts on the same bytes.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string_view>

#include "protocol/protocol.hpp"
#include "protocol/tiles.hpp"

using namespace hs::protocol;

namespace {

[[noreturn]] void fail(const char* what, const char* detail) {
    std::fprintf(stderr, "%s: %s\n", what, detail);
    std::abort();
}

void decode_as(std::span<const uint8_t> bytes, Side sender) {
    Header h;
    auto r = decode_frame(bytes, sender, &h);
    if (auto* e = std::get_if<DecodeError>(&r)) {
        // Every error after a whole header echoes its sequence.
        uint32_t seq = 0;
        if (bytes.size() >= kHeaderBytes)
            std::memcpy(&seq, bytes.data() + 12, 4);
        if (e->sequence != seq)
            fail("a decode error lost the sequence", e->message.c_str());
        return;
    }
    const Message& m = std::get<Message>(r);
    auto again = encode(m, sender, h.sequence);
    if (auto* e = std::get_if<EncodeError>(&again))
        fail("encode refused a decoded message", e->message.c_str());
    const auto& b = std::get<std::vector<uint8_t>>(again);
    if (b.size() != bytes.size() || std::memcmp(b.data(), bytes.data(), b.size()) != 0)
        fail("round trip changed the bytes of a", to_string(type_of(m)));
    // Sparse-tile and lossy-tile payloads of decoded layers.
    if (auto* l = std::get_if<VdLayer>(&m); l && l->encoding != Encoding::kRaw)
        (void)decode_tiles(l->data, l->width, l->height, l->format == PixelFormat::kRgba8 ? 4 : 8);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    std::span<const uint8_t> bytes(data, size);
    decode_as(bytes, Side::kClient);
    decode_as(bytes, Side::kServer);
    // Header-only decoding of any 16-byte prefix.
    if (size >= kHeaderBytes)
        for (Side s : {Side::kClient, Side::kServer}) {
            auto h = decode_header(bytes.first(kHeaderBytes), s);
            uint32_t seq;
            std::memcpy(&seq, data + 12, 4);
            if (auto* e = std::get_if<DecodeError>(&h); e && e->sequence != seq)
                fail("a header error lost the sequence", e->message.c_str());
        }
    // The raw bytes as a tile stream, and as one of lossy tiles (codec 3, tile size 16: the
    // seeds' lossy-tiles-* files) so that mutations reach the JPEG and coverage decoders.
    (void)decode_tiles(bytes, 61, 37, 4);
    {
        // Where the tiles say a layer may be lit: any header, never out of bounds.
        std::vector<uint32_t> first, last;
        if (tile_rows(bytes, 61, 37, first, last))
            for (size_t y = 0; y < first.size(); ++y)
                if (first[y] > last[y] || last[y] > 61)
                    fail("tile_rows gave columns outside the layer", "");
    }
    if (size >= 4) {
        std::vector<uint8_t> lossy(bytes.begin(), bytes.end());
        lossy[0] = 16, lossy[1] = 0, lossy[2] = uint8_t(TileCodec::kJpeg);
        (void)decode_tiles(lossy, 61, 37, 4);
    }
    // UTF-8: sanitizing gives valid UTF-8 and leaves valid UTF-8 alone; truncation keeps it valid.
    const std::string_view text(reinterpret_cast<const char*>(data), size);
    const std::string clean = sanitize_utf8(text);
    if (!is_valid_utf8(clean))
        fail("sanitize_utf8", "produced ill-formed UTF-8");
    if (is_valid_utf8(text) && clean != text)
        fail("sanitize_utf8", "changed valid UTF-8");
    if (!is_valid_utf8(truncate_utf8(clean, size / 2)))
        fail("truncate_utf8", "cut inside a character");
    return 0;
}
