#include "protocol/lossy_tiles.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <csetjmp>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>

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

// One Huffman table as JPEG's DHT segment holds it: the count of codes of each length 1..16
// (bits[0] unused) and the symbols in code order.
struct HuffTable {
    uint8_t bits[17];
    uint8_t val[256];
};

// The table of minimal total length for `freq` (256 symbols; 0: no code), no code longer than 16
// bits and none all ones: the procedure of ITU T.81 Annex K.2, as libjpeg's optimiser runs it.
HuffTable build_table(const std::array<uint64_t, 256>& counts) {
    uint64_t freq[257];
    std::copy(counts.begin(), counts.end(), freq);
    freq[256] = 1;  // a reserved symbol, so that no real code is all ones
    int size[257] = {}, next[257];
    std::fill(std::begin(next), std::end(next), -1);
    for (;;) {
        int c1 = -1, c2 = -1;
        for (int i = 0; i <= 256; ++i)  // the least frequent; the highest symbol on a tie
            if (freq[i] && (c1 < 0 || freq[i] <= freq[c1]))
                c1 = i;
        for (int i = 0; i <= 256; ++i)
            if (freq[i] && i != c1 && (c2 < 0 || freq[i] <= freq[c2]))
                c2 = i;
        if (c2 < 0)
            break;
        freq[c1] += freq[c2];
        freq[c2] = 0;
        for (int c = c1;; c = next[c]) {
            ++size[c];
            if (next[c] < 0) {
                next[c] = c2;
                break;
            }
        }
        for (int c = c2; c >= 0; c = next[c]) ++size[c];
    }
    int bits[258] = {};
    for (int i = 0; i <= 256; ++i)
        if (size[i])
            ++bits[size[i]];
    // Lengths past 16: a pair of them becomes one shorter code and a longer one (Annex K.3).
    for (int i = 257; i > 16; --i)
        while (bits[i] > 0) {
            int j = i - 2;
            while (bits[j] == 0) --j;
            bits[i] -= 2;
            ++bits[i - 1];
            bits[j + 1] += 2;
            --bits[j];
        }
    int longest = 16;
    while (bits[longest] == 0) --longest;
    --bits[longest];  // the reserved symbol's code
    HuffTable t{};
    for (int i = 1; i <= 16; ++i) t.bits[i] = uint8_t(bits[i]);
    int p = 0;
    for (int len = 1; len <= 256; ++len)
        for (int sym = 0; sym < 256; ++sym)
            if (size[sym] == len)
                t.val[p++] = uint8_t(sym);
    return t;
}

// A table that codes every symbol `valid` accepts, close to the fitted `lengths`: a symbol with a
// fitted code weighs 2^(40 - length), one without weighs 1, so the fitted codes keep (nearly)
// their lengths and the rest share the longest codes.
template <size_t N, typename Valid>
HuffTable complete_table(const std::array<uint8_t, N>& lengths, Valid valid) {
    std::array<uint64_t, 256> w{};
    for (int sym = 0; sym < 256; ++sym)
        if (valid(sym))
            w[sym] = size_t(sym) < N && lengths[sym] ? uint64_t(1) << (40 - lengths[sym]) : 1;
    return build_table(w);
}

// The symbols of 8-bit samples: DC differences of 0..11 bits; AC end of block, a run of 16
// zeros, and runs of 0..15 zeros before a coefficient of 1..10 bits.
bool dc_symbol(int s) {
    return s <= 11;
}
bool ac_symbol(int s) {
    return s == 0x00 || s == 0xF0 || ((s & 15) >= 1 && (s & 15) <= 10);
}

// The per-symbol lengths that `t` gives.
template <size_t N>
void lengths_of(const JHUFF_TBL& t, std::array<uint8_t, N>& out) {
    out.fill(0);
    int p = 0;
    for (int len = 1; len <= 16; ++len)
        for (int k = 0; k < t.bits[len]; ++k, ++p)
            if (t.huffval[p] < N)
                out[t.huffval[p]] = uint8_t(len);
}

// The completed tables a layer is coded with.
struct Tables {
    HuffTable dc, ac;
};

// Tables completed from what libjpeg's optimiser fitted to a layer.
Tables complete(const JHUFF_TBL& dc, const JHUFF_TBL& ac) {
    std::array<uint8_t, 12> dl;
    std::array<uint8_t, 256> al;
    lengths_of(dc, dl);
    lengths_of(ac, al);
    return {complete_table(dl, dc_symbol), complete_table(al, ac_symbol)};
}

// Per thread and quality: the tables fitted to a recent layer, when, and how many layers have
// been coded with them. Consecutive layers of one thread show the same scene, mostly from nearby
// poses, so tables fitted to one suit the next ones (`hysar bench encoding`: 1-5 % more bytes
// than fitting every layer, by content and quality) at no statistics pass.
struct Reused {
    bool fitted = false;
    uint32_t layers = 0;  // coded with these tables, the fitted one included
    std::chrono::steady_clock::time_point at{};
    Tables tables;
};
constexpr uint32_t kRefitEvery = 32;            // layers coded with one fit at most
constexpr std::chrono::seconds kRefitAfter{1};  // and never a fit older than this

Reused& reused_for(int quality) {
    thread_local std::unique_ptr<std::array<Reused, 101>> per_quality;
    if (!per_quality)
        per_quality = std::make_unique<std::array<Reused, 101>>();
    return (*per_quality)[size_t(std::clamp(quality, 0, 100))];
}

// The three planes at `planes` (R, G, B, each w x h, one after the other) as a baseline JPEG in
// *buf (malloc'd by libjpeg; the caller frees it), with `tables`, or when null with libjpeg's
// standard tables, or tables fitted to the image (`optimal`), completed into *fitted when
// `fitted` is not null. Planes go in as libjpeg's raw data, so it neither converts colour nor
// copies the rows into its own buffer.
bool jpeg_encode(const uint8_t* planes, uint32_t w, uint32_t h, int quality, const Tables* tables,
                 bool optimal, Tables* fitted, unsigned char** buf, unsigned long* size) {
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
    // One table pair serves all three components (jpeg_set_colorspace's choice for RGB).
    c.optimize_coding = optimal && !tables ? TRUE : FALSE;
    if (tables) {
        for (JHUFF_TBL* t : {c.dc_huff_tbl_ptrs[0], c.ac_huff_tbl_ptrs[0]}) {
            const HuffTable& from = t == c.dc_huff_tbl_ptrs[0] ? tables->dc : tables->ac;
            std::memcpy(t->bits, from.bits, sizeof from.bits);
            std::memcpy(t->huffval, from.val, sizeof from.val);
            t->sent_table = FALSE;
        }
    }
    c.raw_data_in = TRUE;
    jpeg_start_compress(&c, TRUE);
    const size_t plane = size_t(w) * h;
    JSAMPROW rows[3][DCTSIZE];
    JSAMPARRAY comps[3] = {rows[0], rows[1], rows[2]};
    while (c.next_scanline < h) {  // h is a multiple of 16: whole blocks of DCTSIZE rows
        for (int k = 0; k < 3; ++k)
            for (uint32_t i = 0; i < DCTSIZE; ++i)
                rows[k][i] = const_cast<JSAMPROW>(planes + size_t(k) * plane +
                                                  size_t(c.next_scanline + i) * w);
        jpeg_write_raw_data(&c, comps, DCTSIZE);
    }
    jpeg_finish_compress(&c);
    if (fitted && c.optimize_coding)  // the optimiser left its tables in the standard ones' place
        *fitted = complete(*c.dc_huff_tbl_ptrs[0], *c.ac_huff_tbl_ptrs[0]);
    jpeg_destroy_compress(&c);
    return true;
}

// The JPEG in `data` into `img` (w x h): R, G, B planes one after the other (`planar` set) when
// it holds R, G, B at full resolution (what the reference encoder writes: read as libjpeg's raw
// data, with no colour conversion or row copy), else interleaved RGB; null, or why it is refused.
const char* jpeg_decode(const uint8_t* data, size_t size, uint32_t w, uint32_t h, uint8_t* img,
                        bool& planar) {
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
    planar = d.jpeg_color_space == JCS_RGB;
    for (int i = 0; i < 3; ++i)
        planar = planar && d.comp_info[i].h_samp_factor == 1 && d.comp_info[i].v_samp_factor == 1;
    d.dct_method = JDCT_ISLOW;
    if (planar) {
        d.raw_data_out = TRUE;
    } else {
        d.out_color_space = JCS_RGB;
        d.do_fancy_upsampling = FALSE;  // no colour from one packed tile in its neighbour
    }
    jpeg_start_decompress(&d);
    if (planar) {
        const size_t plane = size_t(w) * h;
        JSAMPROW rows[3][DCTSIZE];
        JSAMPARRAY comps[3] = {rows[0], rows[1], rows[2]};
        while (d.output_scanline < h) {  // h is a multiple of 16: whole blocks of rows
            for (int k = 0; k < 3; ++k)
                for (uint32_t i = 0; i < DCTSIZE; ++i)
                    rows[k][i] = img + size_t(k) * plane + size_t(d.output_scanline + i) * w;
            if (jpeg_read_raw_data(&d, comps, DCTSIZE) == 0)
                break;  // cannot happen with a memory source; guards the loop
        }
    } else {
        JSAMPROW rows[16];
        while (d.output_scanline < h) {
            const uint32_t n = std::min<uint32_t>(16, h - d.output_scanline);
            for (uint32_t i = 0; i < n; ++i) rows[i] = img + size_t(d.output_scanline + i) * w * 3;
            if (jpeg_read_scanlines(&d, rows, n) == 0)
                break;  // cannot happen with a memory source; guards the loop
        }
    }
    const bool whole = d.output_scanline == h;
    if (whole)
        jpeg_finish_decompress(&d);
    jpeg_destroy_decompress(&d);
    if (!whole || e.warnings)
        return "lossy tiles: the JPEG is truncated or corrupt";
    return nullptr;
}

// The first x in [from, end) whose bit in the row mask `m` is `set`; `end` when none is.
inline uint32_t next_bit(const uint64_t* m, uint32_t from, uint32_t end, bool set) {
    for (uint32_t x = from; x < end;) {
        uint64_t w = m[x >> 6] >> (x & 63);
        if (!set)
            w = ~w & (~uint64_t(0) >> (x & 63));
        if (w)
            return std::min(end, x + uint32_t(std::countr_zero(w)));
        x = (x | 63) + 1;
    }
    return end;
}

// The tile at `t` into the packed planes at `img` (R, G, B planes `plane` bytes apart, row pitch
// `pitch`) and its coverage bits into `bits` (zeroed). Lit pixels go as they are; the others (and
// the padding past the layer's edge) continue the lit ones: along each row from the nearest lit
// pixel, and rows without one from the nearest row with one, so that the JPEG sees no edge where
// the coverage cuts anyway (an edge costs bits and rings into the lit pixels beside it).
void pack_tile(const uint8_t* raw, size_t stride, const TilePlace& t, uint32_t ts, uint8_t* img,
               size_t plane, size_t pitch, uint8_t* bits) {
    constexpr uint32_t kNone = UINT32_MAX;
    uint32_t lit_row = kNone;  // a row with a lit pixel, the last one seen
    uint32_t row_src[256];     // per row: itself when it has a lit pixel, else kNone
    for (uint32_t y = 0; y < ts; ++y) {
        uint8_t* r = img + size_t(y) * pitch;
        uint8_t* g = r + plane;
        uint8_t* b = g + plane;
        row_src[y] = kNone;
        if (y >= t.ch)
            continue;
        // Every pixel of the row into the planes, and which are lit, without a branch per pixel.
        const uint8_t* src = raw + size_t(t.y0 + y) * stride + size_t(t.x0) * 4;
        const uint32_t cw = t.cw;  // a local: the plane stores could alias `t`
        uint64_t m[4] = {};
        for (uint32_t x0 = 0; x0 < cw; x0 += 64) {
            const uint32_t n = std::min<uint32_t>(64, cw - x0);
            uint64_t word = 0;
            for (uint32_t i = 0; i < n; ++i) {
                const uint8_t* p = src + size_t(x0 + i) * 4;
                uint32_t v;
                std::memcpy(&v, p, 4);
                r[x0 + i] = p[0], g[x0 + i] = p[1], b[x0 + i] = p[2];
                word |= uint64_t(v != 0) << i;
            }
            m[x0 >> 6] = word;
        }
        uint8_t* row_bits = bits + size_t(y) * ts / 8;  // ts is a multiple of 16
        for (uint32_t j = 0; j < ts / 8; ++j) row_bits[j] = uint8_t(m[j >> 3] >> (8 * (j & 7)));
        const uint32_t first = next_bit(m, 0, cw, true);
        if (first == cw)
            continue;
        uint32_t last = first;
        for (int k = 3; k >= 0; --k)
            if (m[k]) {
                last = uint32_t(k) * 64 + 63 - uint32_t(std::countl_zero(m[k]));
                break;
            }
        // Gaps between two lit pixels: the left one's colour up to the middle, the right one's
        // after it.
        for (uint32_t x = first;;) {
            const uint32_t gap = next_bit(m, x, last, false);
            if (gap >= last)
                break;
            const uint32_t right = next_bit(m, gap, last + 1, true), left = gap - 1;
            const uint32_t mid = left + (right - left) / 2;
            for (uint32_t k = gap; k <= mid; ++k) r[k] = r[left], g[k] = g[left], b[k] = b[left];
            for (uint32_t k = mid + 1; k < right; ++k)
                r[k] = r[right], g[k] = g[right], b[k] = b[right];
            x = right;
        }
        std::memset(r, r[first], first);
        std::memset(g, g[first], first);
        std::memset(b, b[first], first);
        std::memset(r + last + 1, r[last], ts - last - 1);
        std::memset(g + last + 1, g[last], ts - last - 1);
        std::memset(b + last + 1, b[last], ts - last - 1);
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
        for (int k = 0; k < 3; ++k)
            std::memcpy(img + k * plane + size_t(y) * pitch, img + k * plane + size_t(from) * pitch,
                        ts);
    }
}

}  // namespace

bool encode_payload(std::vector<uint8_t>& out, const uint8_t* raw, size_t stride,
                    const std::vector<TilePlace>& tiles, uint32_t ts, int quality,
                    std::vector<uint8_t>& scratch, Huffman huffman) {
    if (ts % 16 != 0 || ts > 256)
        return false;  // the packer's row masks and the JPEG's blocks assume these
    const size_t at = out.size();
    out.resize(at + kHead, 0);
    const size_t n = tiles.size();
    if (n == 0)
        return true;
    const uint32_t cols = columns_for(n, ts), rows = uint32_t((n + cols - 1) / cols);
    const uint32_t w = cols * ts, h = rows * ts;
    const size_t plane = size_t(w) * h, bits_per_tile = size_t(ts) * ts / 8;
    scratch.resize(3 * plane + n * bits_per_tile);
    uint8_t* img = scratch.data();
    uint8_t* bits = img + 3 * plane;
    std::memset(bits, 0, n * bits_per_tile);
    const size_t pitch = w;
    for (size_t k = 0; k < n; ++k)
        pack_tile(raw, stride, tiles[k], ts,
                  img + size_t(k / cols) * ts * pitch + size_t(k % cols) * ts, plane, pitch,
                  bits + k * bits_per_tile);
    // Slots past the last tile: grey, cheap to code.
    for (size_t k = n; k < size_t(cols) * rows; ++k)
        for (int c = 0; c < 3; ++c)
            for (uint32_t y = 0; y < ts; ++y)
                std::memset(
                    img + c * plane + (size_t(k / cols) * ts + y) * pitch + size_t(k % cols) * ts,
                    128, ts);
    const size_t bound = ZSTD_compressBound(n * bits_per_tile);
    out.resize(at + kHead + bound);
    const size_t cov = ZSTD_compress(out.data() + at + kHead, bound, bits, n * bits_per_tile, 1);
    if (ZSTD_isError(cov))
        return false;
    out.resize(at + kHead + cov);
    unsigned char* jpeg = nullptr;
    unsigned long jpeg_size = 0;
    quality = std::clamp(quality, 1, 100);
    bool ok;
    if (huffman == Huffman::kReused) {
        Reused& r = reused_for(quality);
        const auto now = std::chrono::steady_clock::now();
        if (!r.fitted || r.layers >= kRefitEvery || now - r.at > kRefitAfter) {
            ok = jpeg_encode(img, w, h, quality, nullptr, true, &r.tables, &jpeg, &jpeg_size);
            r.fitted = ok;
            r.layers = 1;
            r.at = now;
        } else {
            ok = jpeg_encode(img, w, h, quality, &r.tables, false, nullptr, &jpeg, &jpeg_size);
            ++r.layers;
        }
    } else {
        ok = jpeg_encode(img, w, h, quality, nullptr, huffman == Huffman::kOptimal, nullptr, &jpeg,
                         &jpeg_size);
    }
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
    bool planar = false;
    if (const char* why =
            jpeg_decode(data + kHead + cov, size - kHead - cov, w, h, img.data(), planar))
        return why;
    // A pixel's R, G, B lie `step` bytes apart and pixels `px` bytes apart; rows `pitch`.
    const size_t step = planar ? size_t(w) * h : 1, px = planar ? 1 : 3, pitch = size_t(w) * px;
    for (size_t k = 0; k < n; ++k) {
        const TilePlace& t = tiles[k];
        const uint8_t* src = img.data() + (k / cols) * ts * pitch + (k % cols) * ts * px;
        const uint8_t* b = bits.data() + k * bits_per_tile;
        for (uint32_t y = 0; y < t.ch; ++y) {
            uint8_t* dst = rgba + (size_t(t.y0 + y) * width + t.x0) * 4;
            const uint8_t* s = src + size_t(y) * pitch;
            for (uint32_t x = 0; x < t.cw; ++x, dst += 4, s += px) {
                const uint32_t i = y * ts + x;
                if (!((b[i / 8] >> (i % 8)) & 1u))
                    continue;  // stays black: the layer is zeroed
                const uint8_t r = s[0], g = s[step], bl = s[2 * step];
                const bool zero = (r | g | bl) == 0;
                dst[0] = zero ? 1 : r;
                dst[1] = zero ? 1 : g;
                dst[2] = zero ? 1 : bl;
                dst[3] = 255;
            }
        }
    }
    return {};
}

}  // namespace hs::protocol::lossy
