// hysar-projector: a projector client on libhysar-client. Receives projector frames, writes
// them as PNG and shows them; survives the server going away (the window keeps the last frame).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>

#include "clients/client_handle.hpp"
#include "clients/common/common.hpp"
#include "clients/net/args.hpp"
#include "clients/net/connection.hpp"
#include "clients/version.hpp"
#include "clients/window/window.hpp"

using namespace hs::client;
namespace proto = hs::protocol;

static const std::string kUsage =
    std::string(
        "usage: hysar-projector [--connect ADDR] (--token T | --token-file F) [--out DIR]\n"
        "                       [--frames N] [--timeout SECONDS] [--name NAME] [--window]\n"
        "                       [--monitor N] [--screenshot FILE] [--retries N] [--backoff-ms "
        "MS]\n"
        "                       [--tls | --tls-ca FILE | --tls-fingerprint SHA256]\n"
        "\n"
        "  --connect ADDR  HOST:PORT or unix:PATH of hysar serve (default 127.0.0.1:7700)\n"
        "  --out DIR       where frames are written as projector_v<scene version>.png (default\n"
        "                  out/projector)\n"
        "  --frames N      exit after N frames (default 1; 0: until SIGINT or SIGTERM, or the\n"
        "                  window is closed)\n"
        "  --timeout S     with --frames N: give up when no frame arrives for S seconds (default\n"
        "                  60); with --frames 0 it waits for new scenes indefinitely\n"
        "  --window        show each frame in a window (GLFW); with --monitor N, full-screen on\n"
        "                  monitor N; while the server is away the window keeps the last frame\n"
        "  --screenshot F  with --window: save what the window shows after the last frame as "
        "PNG\n"
        "  --version       print the version, git commit and build type, and exit\n") +
    kConnectionUsage +
    "\n"
    "Exit status: 0 ok; 1 the run failed (no frame in time, reconnecting gave up, a bad frame,\n"
    "an Error from the server); 2 bad arguments or no first session (server unreachable or the\n"
    "token refused).\n"
    "Example: hysar-projector --connect 127.0.0.1:7700 --token-file token --frames 0\n";

namespace {

// A projector frame: written to OUT as projector_vN.png and shown in the window. False when
// the file cannot be written.
bool take_frame(const Event& e, const std::filesystem::path& out, ImageWindow* window) {
    const hysar_image& im = e.image;
    const auto format = proto::PixelFormat(im.format);
    std::string file = (out / ("projector_v" + std::to_string(e.scene_version) + ".png")).string();
    if (!write_layer_png(file, im.width, im.height, format, {im.pixels, im.size_bytes})) {
        std::fprintf(stderr, "hysar-projector: cannot write %s\n", file.c_str());
        return false;
    }
    std::printf("projector frame v%u %ux%u -> %s\n", e.scene_version, im.width, im.height,
                file.c_str());
    std::fflush(stdout);
    if (window && format == proto::PixelFormat::kRgba8) {
        std::vector<uint8_t> px(im.pixels, im.pixels + im.size_bytes);
        for (size_t i = 3; i < px.size(); i += 4) px[i] = 255;
        window->show(px, im.width, im.height);
    }
    return true;
}

// Takes projector frames until `frames_wanted` (0: until stopped), a frame is late by
// `timeout_ms`, the window is closed or the session ends; the exit status (0 or 1). Server
// errors are counted in `server_errors` and the frames go on.
int receive_frames(hysar_client* client, ImageWindow* window, const std::filesystem::path& out,
                   int64_t frames_wanted, int timeout_ms, int64_t& server_errors) {
    int64_t frames = 0;
    auto last_frame = std::chrono::steady_clock::now();
    // The window is polled every 50 ms whatever the network does: it stays responsive and
    // keeps showing the last frame while the library reconnects.
    while (!stop_requested() && (frames_wanted == 0 || frames < frames_wanted)) {
        Event e;
        if (hysar_client_poll(client, window ? 50 : 200, &e) != HYSAR_OK) {
            std::fprintf(stderr, "hysar-projector: %s\n", hysar_last_error());
            return 1;
        }
        if (window && !window->poll())
            break;
        if (e.kind == HYSAR_EVENT_NONE) {
            const auto waited = std::chrono::steady_clock::now() - last_frame;
            if (frames_wanted != 0 && waited >= std::chrono::milliseconds(timeout_ms)) {
                std::fprintf(stderr, "hysar-projector: no frame within %s s (--timeout)\n",
                             format_number(timeout_ms / 1000.0).c_str());
                return 1;
            }
            continue;
        }
        if (report_connection("hysar-projector", e))
            continue;
        if (e.kind == HYSAR_EVENT_CLOSED) {
            std::fprintf(stderr, "hysar-projector: %s\n", e.text);
            return 1;
        }
        if (e.kind == HYSAR_EVENT_SERVER_ERROR) {
            ++server_errors;  // reported, and the exit status says so; frames may still come
            std::fprintf(stderr, "hysar-projector: server error: %s\n", e.text);
            continue;
        }
        if (e.kind != HYSAR_EVENT_PROJECTOR_FRAME)
            continue;
        last_frame = std::chrono::steady_clock::now();
        if (!take_frame(e, out, window))
            return 1;
        ++frames;
    }
    return 0;
}

int projector_main(int argc, char** argv) {
    Args args(argc, argv,
              with(kConnectionOptions, {"--connect", "--token", "--token-file", "--out", "--frames",
                                        "--timeout", "--name", "--monitor", "--screenshot"}),
              with(kConnectionFlags, {"--window"}), kUsage.c_str(),
              HYSAR_CLIENT_VERSION_TEXT("hysar-projector"));
    // Everything on the command line is checked before the network is touched.
    const std::string address = args.get("--connect", "127.0.0.1:7700");
    if (auto addr = parse_address(address); auto* bad = std::get_if<std::string>(&addr))
        args.fail("--connect '" + address + "': " + *bad);
    const std::string token = args.token(proto::kMaxTokenBytes);
    const TlsOptions tls = args.tls_options();
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
    const hysar_client_config config =
        client_config(args, address, token, name, HYSAR_ROLE_PROJECTOR, tls);

    std::unique_ptr<ImageWindow> window;
    if (args.has("--window")) {
        auto w = ImageWindow::open("hysar-projector", 960, 600, monitor);
        if (auto* e = std::get_if<std::string>(&w)) {
            std::fprintf(stderr, "hysar-projector: --window: %s\n", e->c_str());
            return 2;
        }
        window = std::move(std::get<std::unique_ptr<ImageWindow>>(w));
    }
    auto connected = connect_client(config);
    if (auto* e = std::get_if<std::string>(&connected)) {
        std::fprintf(stderr, "hysar-projector: %s\n", e->c_str());
        return 2;
    }
    hysar_client* client = std::get<ClientPtr>(connected).get();
    stop_on_signals();
    int64_t server_errors = 0;
    const int rc =
        receive_frames(client, window.get(), out, frames_wanted, timeout_ms, server_errors);
    if (window && !screenshot.empty()) {
        uint32_t w = 0, h = 0;
        auto px = window->read_back(&w, &h);
        if (!write_layer_png(screenshot, w, h, proto::PixelFormat::kRgba8, px)) {
            std::fprintf(stderr, "hysar-projector: --screenshot '%s': cannot write it\n",
                         screenshot.c_str());
            return 1;
        }
    }
    return rc ? rc : server_errors ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
    return run_main("hysar-projector", argc, argv, projector_main);
}
