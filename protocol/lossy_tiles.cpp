#include "protocol/lossy_tiles.hpp"

#include <algorithm>
#include <csetjmp>
#include <cstdio>
#include <cstdlib>
#include <cstring>

// jpeglib.h wants size_t and FILE declared first.
#include <jpeglib.h>
#include <zstd.h>

namespace hs::protocol::lossy {

namespace {

// Payload: u16 columns, u16 reserved, u32 coverage bytes, the coverage (zstd), the JPEG.
constexpr size_t kHead = 8;
constexpr uint32_t kMaxJpegSide = 65500;  // JPEG's own limit is 65535

// The packed image's tiles per row: at most 32 unless its height would pass JPEG's limit.
uint32_t columns_for(size_t n, uint32_t ts) {
    const size_t rows_max = kMaxJpegSide / ts;
    return uint32_t(std::max<size_t>(std::min<size_t>(n, 32), (n + rows_max - 1) / rows_max));
}

// libjpeg reports errors through a callback that must not return: it jumps back to the call.
// The functions that set the jump point hold no object with a destructor.
struct ErrorJump {
    jpeg_error_mgr mgr;
    std::jmp_buf jump;
    int warnings;
};
[[noreturn]] void on_error(j_common_ptr c) {
    std::longjmp(reinterpret_cast<ErrorJump*>(c->err)->jump, 1);
}
void on_message(j_common_ptr c, int level) {
    if (level < 0)
        ++reinterpret_cast<ErrorJump*>(c->err)->warnings;  // corrupt data: counted, not printed
}
void hook(ErrorJump& e) {
    jpeg_std_error(&e.mgr);
    e.mgr.error_exit = on_error;
    e.mgr.emit_message = on_message;
    e.warnings = 0;
}

// `rgb` (w x h x 3) as a baseline JPEG in *buf (malloc'd by libjpeg; the caller frees it).
bool jpeg_encode(const uint8_t* rgb, uint32_t w, uint32_t h, int quality, unsigned char** buf,
                 unsigned long* size) {
    jpeg_compress_struct c;
    ErrorJump e;
    hook(e);
    c.err = &e.mgr;
    if (setjmp(e.jump)) {
        jpeg_destroy_compress(&c);
        return false;
    }
    jpeg_create_compress(&c);
    jpeg_mem_dest(&c, buf, size);
    c.image_width = w;
    c.image_height = h;
    c.input_components = 3;
    c.in_color_space = JCS_RGB;
    jpeg_set_defaults(&c);
    // RGB samples, no YCbCr: the colour transform's 8-bit rounding alone costs up to 3.5
    // CIEDE2000 on dark saturated pixels at any quality (`hysar bench encoding`, README), and
    // 4:4:4, since subsampled chroma would bleed between packed tiles that are not neighbours.
    jpeg_set_colorspace(&c, JCS_RGB);
    jpeg_set_quality(&c, quality, TRUE);
    for (int i = 0; i < c.num_components; ++i)
        c.comp_info[i].h_samp_factor = c.comp_info[i].v_samp_factor = 1;
    c.dct_method = JDCT_ISLOW;
    c.optimize_coding = TRUE;  // a fifth fewer bytes than the standard Huffman tables
    jpeg_start_compress(&c, TRUE);
    JSAMPROW rows[16];
    while (c.next_scanline < h) {
        const uint32_t n = std::min<uint32_t>(16, h - c.next_scanline);
        for (uint32_t i = 0; i < n; ++i)
            rows[i] = const_cast<JSAMPROW>(rgb + size_t(c.next_scanline + i) * w * 3);
        jpeg_write_scanlines(&c, rows, n);
    }
    jpeg_finish_compress(&c);
    jpeg_destroy_compress(&c);
    return true;
}

// The JPEG in `data` into `rgb` (w x h x 3); null, or why it is refused.
const char* jpeg_decode(const uint8_t* data, size_t size, uint32_t w, uint32_t h, uint8_t* rgb) {
    jpeg_decompress_struct d;
    ErrorJump e;
    hook(e);
    d.err = &e.mgr;
    const char* volatile why = "lossy tiles: the JPEG is corrupt";
    if (setjmp(e.jump)) {
        jpeg_destroy_decompress(&d);
        return why;
    }
    jpeg_create_decompress(&d);
    jpeg_mem_src(&d, data, static_cast<unsigned long>(size));
    if (jpeg_read_header(&d, TRUE) != JPEG_HEADER_OK) {
        jpeg_destroy_decompress(&d);
        return "lossy tiles: the JPEG has no image";
    }
    if (d.image_width != w || d.image_height != h) {
        jpeg_destroy_decompress(&d);
        return "lossy tiles: the JPEG's size differs from the packed tiles'";
    }
    if (d.num_components != 3 ||
        (d.jpeg_color_space != JCS_RGB && d.jpeg_color_space != JCS_YCbCr)) {
        jpeg_destroy_decompress(&d);
        return "lossy tiles: the JPEG must have three components, RGB or YCbCr";
    }
    if (d.progressive_mode || d.arith_code) {
        jpeg_destroy_decompress(&d);
        return "lossy tiles: the JPEG must be baseline (sequential, Huffman)";
    }
    d.out_color_space = JCS_RGB;
    d.dct_method = JDCT_ISLOW;
    d.do_fancy_upsampling = FALSE;  // no colour from one packed tile in its neighbour
    jpeg_start_decompress(&d);
    JSAMPROW rows[16];
    while (d.output_scanline < h) {
        const uint32_t n = std::min<uint32_t>(16, h - d.output_scanline);
        for (uint32_t i = 0; i < n; ++i) rows[i] = rgb + size_t(d.output_scanline + i) * w * 3;
        if (jpeg_read_scanlines(&d, rows, n) == 0)
            break;  // cannot happen with a memory source; guards the loop
    }
    const bool whole = d.output_scanline == h;
    if (whole)
        jpeg_finish_decompress(&d);
    jpeg_destroy_decompress(&d);
    if (!whole || e.warnings)
        return "lossy tiles: the JPEG is truncated or corrupt";
    return nullptr;
}

inline bool lit(const uint8_t* p) {
    uint32_t v;
    std::memcpy(&v, p, 4);
    return v != 0;
}

// The tile at `t` into the packed image at `img` (row pitch `pitch`, RGB) and its coverage bits
// into `bits`. Lit pixels go as they are; the others (and the padding past the layer's edge)
// continue the lit ones: along each row from the nearest lit pixel, and rows without one from
// the nearest row with one, so that the JPEG sees no edge where the coverage cuts anyway (an
// edge costs bits and rings into the lit pixels beside it).
void pack_tile(const uint8_t* raw, size_t stride, const TilePlace& t, uint32_t ts, uint8_t* img,
               size_t pitch, uint8_t* bits) {
    constexpr uint32_t kNone = UINT32_MAX;
    uint32_t lit_row = kNone;  // a row with a lit pixel, the last one seen
    uint32_t row_src[256];     // per row: itself when it has a lit pixel, else kNone
    for (uint32_t y = 0; y < ts; ++y) {
        uint8_t* dst = img + size_t(y) * pitch;
        uint32_t first = kNone, last = kNone;
        if (y < t.ch) {
            const uint8_t* src = raw + size_t(t.y0 + y) * stride + size_t(t.x0) * 4;
            for (uint32_t x = 0; x < t.cw; ++x) {
                const uint8_t* p = src + size_t(x) * 4;
                if (!lit(p))
                    continue;
                const uint32_t i = y * ts + x;
                bits[i / 8] |= uint8_t(1u << (i % 8));
                uint8_t* d = dst + size_t(x) * 3;
                d[0] = p[0], d[1] = p[1], d[2] = p[2];
                if (first == kNone)
                    first = x;
                else if (last != kNone && last + 1 < x)
                    // The gap between two lit pixels: the left one's colour up to the middle,
                    // the right one's after it.
                    for (uint32_t g = last + 1; g < x; ++g)
                        std::memcpy(dst + size_t(g) * 3,
                                    dst + size_t(g - last <= x - g ? last : x) * 3, 3);
                last = x;
            }
        }
        if (first == kNone) {
            row_src[y] = kNone;
            continue;
        }
        for (uint32_t x = 0; x < first; ++x) std::memcpy(dst + size_t(x) * 3, dst + first * 3, 3);
        for (uint32_t x = last + 1; x < ts; ++x)
            std::memcpy(dst + size_t(x) * 3, dst + last * 3, 3);
        row_src[y] = y;
        lit_row = y;
    }
    if (lit_row == kNone)
        return;  // a stored tile has a lit pixel; cannot happen
    // Rows without a lit pixel: the nearest row with one (the one above on a tie).
    uint32_t above = kNone;
    for (uint32_t y = 0; y < ts; ++y) {
        if (row_src[y] != kNone) {
            above = y;
            continue;
        }
        uint32_t below = y + 1;
        while (below < ts && row_src[below] == kNone) ++below;
        uint32_t from;
        if (above == kNone)
            from = below;
        else if (below >= ts)
            from = above;
        else
            from = y - above <= below - y ? above : below;
        std::memcpy(img + size_t(y) * pitch, img + size_t(from) * pitch, size_t(ts) * 3);
    }
}

}  // namespace

bool encode_payload(std::vector<uint8_t>& out, const uint8_t* raw, size_t stride,
                    const std::vector<TilePlace>& tiles, uint32_t ts, int quality,
                    std::vector<uint8_t>& scratch) {
    const size_t at = out.size();
    out.resize(at + kHead, 0);
    const size_t n = tiles.size();
    if (n == 0)
        return true;
    const uint32_t cols = columns_for(n, ts), rows = uint32_t((n + cols - 1) / cols);
    const uint32_t w = cols * ts, h = rows * ts;
    const size_t img_bytes = size_t(w) * h * 3, bits_per_tile = size_t(ts) * ts / 8;
    scratch.resize(img_bytes + n * bits_per_tile);
    uint8_t* img = scratch.data();
    uint8_t* bits = img + img_bytes;
    std::memset(bits, 0, n * bits_per_tile);
    const size_t pitch = size_t(w) * 3;
    for (size_t k = 0; k < n; ++k)
        pack_tile(raw, stride, tiles[k], ts,
                  img + size_t(k / cols) * ts * pitch + size_t(k % cols) * ts * 3, pitch,
                  bits + k * bits_per_tile);
    // Slots past the last tile: grey, cheap to code.
    for (size_t k = n; k < size_t(cols) * rows; ++k)
        for (uint32_t y = 0; y < ts; ++y)
            std::memset(img + (size_t(k / cols) * ts + y) * pitch + size_t(k % cols) * ts * 3, 128,
                        size_t(ts) * 3);
    const size_t bound = ZSTD_compressBound(n * bits_per_tile);
    out.resize(at + kHead + bound);
    const size_t cov = ZSTD_compress(out.data() + at + kHead, bound, bits, n * bits_per_tile, 1);
    if (ZSTD_isError(cov))
        return false;
    out.resize(at + kHead + cov);
    unsigned char* jpeg = nullptr;
    unsigned long jpeg_size = 0;
    const bool ok = jpeg_encode(img, w, h, std::clamp(quality, 1, 100), &jpeg, &jpeg_size);
    if (ok) {
        out.insert(out.end(), jpeg, jpeg + jpeg_size);
        const uint16_t c16 = uint16_t(cols);
        const uint32_t cov32 = uint32_t(cov);
        std::memcpy(out.data() + at, &c16, 2);
        std::memcpy(out.data() + at + 4, &cov32, 4);
    }
    std::free(jpeg);
    return ok;
}

std::string decode_payload(const uint8_t* data, size_t size, const std::vector<TilePlace>& tiles,
                           uint32_t ts, uint8_t* rgba, uint32_t width) {
    if (ts % 16 != 0)
        return "lossy tiles: tile_size must be a multiple of 16";
    if (size < kHead)
        return "lossy tiles: shorter than their header";
    uint16_t cols, reserved;
    uint32_t cov;
    std::memcpy(&cols, data, 2);
    std::memcpy(&reserved, data + 2, 2);
    std::memcpy(&cov, data + 4, 4);
    const size_t n = tiles.size();
    if (reserved != 0)
        return "lossy tiles: the reserved field is not 0";
    if (n == 0) {
        if (cols != 0 || cov != 0 || size != kHead)
            return "lossy tiles: no tile is stored, yet the payload holds data";
        return {};
    }
    if (cols == 0 || cols > n)
        return "lossy tiles: columns " + std::to_string(cols) + " is out of 1.." +
               std::to_string(n);
    const size_t rows = (n + cols - 1) / cols;
    if (size_t(cols) * ts > kMaxJpegSide || rows * ts > kMaxJpegSide)
        return "lossy tiles: the packed image is larger than a JPEG can be";
    if (cov > size - kHead)
        return "lossy tiles: the coverage is longer than the payload";
    const size_t bits_per_tile = size_t(ts) * ts / 8;
    std::vector<uint8_t> bits(n * bits_per_tile);
    const size_t got = ZSTD_decompress(bits.data(), bits.size(), data + kHead, cov);
    if (ZSTD_isError(got) || got != bits.size())
        return "lossy tiles: the coverage is corrupt or of the wrong size";
    const uint32_t w = uint32_t(cols) * ts, h = uint32_t(rows) * ts;
    std::vector<uint8_t> img(size_t(w) * h * 3);
    if (const char* why = jpeg_decode(data + kHead + cov, size - kHead - cov, w, h, img.data()))
        return why;
    const size_t pitch = size_t(w) * 3;
    for (size_t k = 0; k < n; ++k) {
        const TilePlace& t = tiles[k];
        const uint8_t* src = img.data() + (k / cols) * ts * pitch + (k % cols) * ts * 3;
        const uint8_t* b = bits.data() + k * bits_per_tile;
        for (uint32_t y = 0; y < t.ch; ++y) {
            uint8_t* dst = rgba + (size_t(t.y0 + y) * width + t.x0) * 4;
            const uint8_t* s = src + size_t(y) * pitch;
            for (uint32_t x = 0; x < t.cw; ++x, dst += 4, s += 3) {
                const uint32_t i = y * ts + x;
                if (!((b[i / 8] >> (i % 8)) & 1u))
                    continue;  // stays black: the layer is zeroed
                const bool zero = (s[0] | s[1] | s[2]) == 0;
                dst[0] = zero ? 1 : s[0];
                dst[1] = zero ? 1 : s[1];
                dst[2] = zero ? 1 : s[2];
                dst[3] = 255;
            }
        }
    }
    return {};
}

}  // namespace hs::protocol::lossy
