// libFuzzer target: any bytes given to the decoder give a message or a DecodeError, never a
// crash, a sanitizer report or an unbounded allocation; a message that decodes re-encodes to
// the same bytes.
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "protocol/protocol.hpp"
#include "protocol/tiles.hpp"

using namespace hs::protocol;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    std::span<const uint8_t> bytes(data, size);
    Header h;
    auto r = decode_frame(bytes, &h);
    if (auto* m = std::get_if<Message>(&r)) {
        auto again = encode(*m, h.sequence);
        if (again.size() != size || std::memcmp(again.data(), data, size) != 0) {
            std::fprintf(stderr, "round trip changed the bytes of a %s\n", to_string(type_of(*m)));
            std::abort();
        }
    }
    // Sparse-tile payloads of decoded layers, and the raw bytes as a tile stream.
    if (auto* m = std::get_if<Message>(&r))
        if (auto* l = std::get_if<VdLayer>(m); l && l->encoding == Encoding::kSparseTiles)
            (void)decode_tiles(l->data, l->width, l->height,
                               l->format == PixelFormat::kRgba8 ? 4 : 8);
    (void)decode_tiles(bytes, 61, 37, 4);
    // Header-only decoding of any 16-byte prefix.
    if (size >= kHeaderBytes)
        (void)decode_header(bytes.first(kHeaderBytes));
    return 0;
}
