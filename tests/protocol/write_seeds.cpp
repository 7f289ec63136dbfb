// Writes one valid frame of every message type into a folder: the decoder fuzzer's seeds.
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "protocol/protocol.hpp"

using namespace hs::protocol;

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: write_seeds DIR\n");
        return 2;
    }
    std::filesystem::create_directories(argv[1]);
    VdLayer layer;
    layer.width = layer.height = 1;
    layer.data = {1, 2, 3, 4};
    ProjectorFrame pf;
    pf.width = pf.height = 1;
    pf.data = {1, 2, 3, 4};
    const Message all[] = {Hello{Role::kHmd, "token", "name"},
                           Welcome{1, 2, 3},
                           RegisterDisplay{64, 32, 50, 50, 31.5, 15.5, 0.063, PixelFormat::kRgba8,
                                           Encoding::kRaw, FrameMode::kOnRequest},
                           Pose{1, {0, 1, 0}, {1, 0, 0, 0}},
                           FrameRequest{},
                           layer,
                           pf,
                           SceneUpdate{"{}"},
                           StatsRequest{},
                           Stats{"{}"},
                           Ping{1},
                           Pong{1, 2},
                           Error{ErrorCode::kMalformed, "x"},
                           Bye{0}};
    for (const Message& m : all) {
        auto bytes = encode(m, 1);
        std::ofstream(std::filesystem::path(argv[1]) / to_string(type_of(m)), std::ios::binary)
            .write((const char*)bytes.data(), std::streamsize(bytes.size()));
    }
    return 0;
}
