// hysar-projector: a projector client. Receives projector frames and writes them as PNG.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>

#include "clients/args.hpp"
#include "clients/common.hpp"
#include "clients/connection.hpp"
#include "clients/window.hpp"

using namespace hs::client;
namespace proto = hs::protocol;

static const char* kUsage =
    "usage: hysar-projector [--connect ADDR] (--token T | --token-file F) [--out DIR] [--frames "
    "N]\n"
    "                       [--timeout SECONDS] [--name NAME] [--window] [--monitor N]\n"
    "                       [--screenshot FILE]\n"
    "\n"
    "  --connect ADDR  HOST:PORT or unix:PATH of hysar serve (default 127.0.0.1:7700)\n"
    "  --out DIR       where frames are written as projector_v<scene version>.png (default "
    "out/projector)\n"
    "  --frames N      exit after N frames (default 1; 0 = run until the server says Bye)\n"
    "  --timeout S     give up when no frame arrives for S seconds (default 60; with --frames 0\n"
    "                it waits for new scenes indefinitely, pinging the server)\n"
    "  --window        show each frame in a window (GLFW); with --monitor N, full-screen on "
    "monitor N\n"
    "  --screenshot F  with --window: save what the window shows after the last frame as PNG\n"
    "\n"
    "Exit status: 0 ok; 1 the run failed (no frame in time, a lost connection, a bad frame, an\n"
    "Error from the server);\n"
    "2 bad arguments or no session (server unreachable, closed, or refused the token).\n"
    "Example: hysar-projector --connect 127.0.0.1:7700 --token-file token --frames 0\n";

namespace {

int projector_main(int argc, char** argv) {
    Args args(argc, argv,
              {"--connect", "--token", "--token-file", "--out", "--frames", "--timeout", "--name",
               "--monitor", "--screenshot"},
              {"--window"}, kUsage);
    // Everything on the command line is checked before the network is touched.
    const std::string address = args.get("--connect", "127.0.0.1:7700");
    if (auto addr = parse_address(address); auto* bad = std::get_if<std::string>(&addr))
        args.fail("--connect '" + address + "': " + *bad);
    const std::string token = args.token(proto::kMaxTokenBytes);
    const std::string name = args.text("--name", "projector", proto::kMaxNameBytes);
    const int64_t frames_wanted = args.integer("--frames", 1, 0, 1000000000);
    const int timeout_ms = int(args.number("--timeout", 60, 0.1, 1e6) * 1000);
    if (!args.has("--window") && (args.has("--monitor") || args.has("--screenshot")))
        args.fail(std::string(args.has("--monitor") ? "--monitor" : "--screenshot") +
                  " needs --window");
    const int monitor = int(args.integer("--monitor", -1, -1, 64));
    const std::string screenshot =
        args.has("--screenshot") ? args.output_path("--screenshot", "") : "";
    const std::filesystem::path out = args.get("--out", "out/projector");
    if (auto err = make_output_dir(out.string()))
        args.fail("--out " + *err);

    std::unique_ptr<ImageWindow> window;
    if (args.has("--window")) {
        auto w = ImageWindow::open("hysar-projector", 960, 600, monitor);
        if (auto* e = std::get_if<std::string>(&w)) {
            std::fprintf(stderr, "hysar-projector: --window: %s\n", e->c_str());
            return 2;
        }
        window = std::move(std::get<std::unique_ptr<ImageWindow>>(w));
    }
    auto c = Connection::open(address);
    if (auto* e = std::get_if<std::string>(&c)) {
        std::fprintf(stderr, "hysar-projector: --connect: %s\n", e->c_str());
        return 2;
    }
    auto& conn = *std::get<std::unique_ptr<Connection>>(c);
    if (auto err = conn.hello(proto::Role::kProjector, token, name)) {
        std::fprintf(stderr, "hysar-projector: %s: %s\n", address.c_str(), err->c_str());
        return 2;
    }
    int64_t frames = 0, server_errors = 0;
    // A projector only receives: a Ping every kKeepAliveMs keeps the server's idle timeout
    // (docs/OPERATIONS.md) from closing the session while it waits for a new scene.
    constexpr int kKeepAliveMs = 30000;
    auto last_message = std::chrono::steady_clock::now();
    while (frames_wanted == 0 || frames < frames_wanted) {
        auto r = conn.receive(std::min(timeout_ms, kKeepAliveMs));
        if (std::holds_alternative<std::monostate>(r)) {
            const auto waited = std::chrono::steady_clock::now() - last_message;
            if (frames_wanted != 0 && waited >= std::chrono::milliseconds(timeout_ms)) {
                std::fprintf(stderr, "hysar-projector: no frame within %s s (--timeout)\n",
                             format_number(timeout_ms / 1000.0).c_str());
                return 1;
            }
            if (!conn.send(proto::Ping{now_ns()})) {
                std::fprintf(stderr, "hysar-projector: the server closed the connection\n");
                return 1;
            }
            continue;
        }
        last_message = std::chrono::steady_clock::now();
        if (auto* e = std::get_if<std::string>(&r)) {
            if (frames_wanted == 0)
                break;  // the server closed
            std::fprintf(stderr, "hysar-projector: %s\n", e->c_str());
            return 1;
        }
        const auto& m = std::get<proto::Message>(r);
        if (std::holds_alternative<proto::Bye>(m))
            break;
        if (auto* e = std::get_if<proto::Error>(&m)) {
            ++server_errors;  // reported, and the exit status says so; frames may still come
            std::fprintf(stderr, "hysar-projector: server error: %s\n", describe(*e).c_str());
        }
        if (auto* f = std::get_if<proto::ProjectorFrame>(&m)) {
            std::string file =
                (out / ("projector_v" + std::to_string(f->scene_version) + ".png")).string();
            auto raw = raw_pixels(f->width, f->height, f->format, f->encoding, f->data);
            if (auto* e = std::get_if<std::string>(&raw)) {
                std::fprintf(stderr, "hysar-projector: frame v%u: %s\n", f->scene_version,
                             e->c_str());
                return 1;
            }
            if (!write_layer_png(file, f->width, f->height, f->format,
                                 std::get<std::vector<uint8_t>>(raw))) {
                std::fprintf(stderr, "hysar-projector: cannot write %s\n", file.c_str());
                return 1;
            }
            std::printf("projector frame v%u %ux%u -> %s\n", f->scene_version, f->width, f->height,
                        file.c_str());
            if (window) {
                auto px = std::get<std::vector<uint8_t>>(raw);
                if (f->format == proto::PixelFormat::kRgba8) {
                    for (size_t i = 3; i < px.size(); i += 4) px[i] = 255;
                    window->show(px, f->width, f->height);
                }
                if (!window->poll())
                    break;
            }
            ++frames;
        }
    }
    if (window && !screenshot.empty()) {
        uint32_t w = 0, h = 0;
        auto px = window->read_back(&w, &h);
        if (!write_layer_png(screenshot, w, h, proto::PixelFormat::kRgba8, px)) {
            std::fprintf(stderr, "hysar-projector: --screenshot '%s': cannot write it\n",
                         screenshot.c_str());
            return 1;
        }
    }
    conn.send(proto::Bye{0});
    return server_errors ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
    return run_main("hysar-projector", argc, argv, projector_main);
}
