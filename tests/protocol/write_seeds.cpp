// Writes one valid frame of every message type, and the malformed-frame corpus of both sides,
// into a folder: the decoder fuzzer's seeds.
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "protocol/protocol.hpp"
#include "protocol/tiles.hpp"
#include "tests/protocol/corpus.hpp"

using namespace hs::protocol;

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: write_seeds DIR\n");
        return 2;
    }
    const std::filesystem::path dir(argv[1]);
    std::filesystem::create_directories(dir);
    auto write = [&](const std::string& name, const std::vector<uint8_t>& bytes) {
        std::ofstream(dir / name, std::ios::binary)
            .write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    };
    for (const Message& m : corpus::samples()) {
        const Side sender = may_send(type_of(m), Side::kClient) ? Side::kClient : Side::kServer;
        auto bytes = encode(m, sender, 1);
        if (auto* e = std::get_if<EncodeError>(&bytes)) {
            std::fprintf(stderr, "write_seeds: %s\n", e->message.c_str());
            return 1;
        }
        write(to_string(type_of(m)), std::get<std::vector<uint8_t>>(bytes));
    }
    // The corpus's frames, whose payloads exceed no limit (the oversized ones are headers only).
    for (Side sender : {Side::kClient, Side::kServer}) {
        const auto frames = corpus::malformed_frames(sender);
        for (size_t i = 0; i < frames.size(); ++i)
            write(std::string("corpus-") + to_string(sender) + "-" + std::to_string(i),
                  frames[i].bytes);
    }
    // Lossy tiles of a 61 x 37 layer (the fuzzer's tile-stream size): a few lit discs.
    for (int seed = 0; seed < 3; ++seed) {
        std::vector<uint8_t> img(size_t(61) * 37 * 4, 0);
        for (int y = 0; y < 37; ++y)
            for (int x = 0; x < 61; ++x) {
                const int dx = x - 12 - 15 * seed, dy = y - 18;
                if (dx * dx + dy * dy < 64 + 40 * seed) {
                    uint8_t* p = &img[(size_t(y) * 61 + x) * 4];
                    p[0] = uint8_t(200 - dx * dx), p[1] = uint8_t(120 + 5 * dy), p[2] = 60,
                    p[3] = 255;
                }
            }
        write("lossy-tiles-" + std::to_string(seed),
              encode_tiles(img, 61, 37, 4, TileCodec::kJpeg, 16, 40 + 20 * seed));
    }
    return 0;
}
