// Writes one valid frame of every message type, and the malformed-frame corpus of both sides,
// into a folder: the decoder fuzzer's seeds.
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "protocol/protocol.hpp"
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
    return 0;
}
