// `hysar serve`: the render server on a scene, until SIGINT or SIGTERM.
#include <csignal>
#include <cstdio>
#include <fstream>
#include <random>
#include <sstream>
#include <thread>

#include <fmt/format.h>

#include "commands.hpp"
#include "core/log.hpp"
#include "scene/config.hpp"
#include "stream/server.hpp"

namespace hs::cli {

namespace {

const char* kServeHelp =
    "usage: hysar serve [--scene FILE] [--listen HOST:PORT] [--unix PATH] [--token-file FILE]\n"
    "                   [--device auto|cpu|gpu] [--stats-file FILE]\n"
    "\n"
    "  --scene FILE       scene JSON (default: the embedded experiment-1 room)\n"
    "  --listen HOST:PORT TCP address (default 127.0.0.1:7700; use 0.0.0.0:PORT for a real room)\n"
    "  --unix PATH        also listen on a Unix socket\n"
    "  --token-file FILE  the installation's shared token (first line); without it a random\n"
    "                     token is generated and printed\n"
    "  --stats-file FILE  write the final stats JSON here on shutdown\n";

std::string random_token() {
    std::random_device rd;
    std::string t;
    static const char* hex = "0123456789abcdef";
    for (int i = 0; i < 32; ++i) t += hex[rd() % 16];
    return t;
}

std::atomic<bool> g_stop{false};
extern "C" void on_signal(int) {
    g_stop.store(true);
}

}  // namespace

int run_serve(const std::vector<std::string>& args) {
    std::optional<std::string> scene_path, token_file, stats_file;
    stream::ServerCreateInfo info;
    gpu::DeviceCreateInfo di = gpu::device_info_from_environment();
    for (size_t i = 0; i < args.size(); ++i) {
        const std::string& a = args[i];
        auto value = [&]() -> std::optional<std::string> {
            if (i + 1 >= args.size())
                return std::nullopt;
            return args[++i];
        };
        std::optional<std::string> v;
        if (a == "--help" || a == "-h") {
            std::fputs(kServeHelp, stdout);
            return 0;
        }
        if (a != "--scene" && a != "--listen" && a != "--unix" && a != "--token-file" &&
            a != "--device" && a != "--stats-file") {
            std::fprintf(stderr, "hysar serve: unknown option '%s'\n\n%s", a.c_str(), kServeHelp);
            return 2;
        }
        if (!(v = value())) {
            std::fprintf(stderr, "hysar serve: %s needs a value\n", a.c_str());
            return 2;
        }
        if (a == "--scene")
            scene_path = v;
        else if (a == "--unix")
            info.unix_path = *v;
        else if (a == "--token-file")
            token_file = v;
        else if (a == "--stats-file")
            stats_file = v;
        else if (a == "--device") {
            if (*v == "cpu")
                di.preference = gpu::DevicePreference::kCpu;
            else if (*v == "gpu")
                di.preference = gpu::DevicePreference::kGpu;
            else if (*v == "auto")
                di.preference = gpu::DevicePreference::kAuto;
            else {
                std::fprintf(stderr, "hysar serve: --device: '%s' is not auto, cpu or gpu\n",
                             v->c_str());
                return 2;
            }
        } else if (a == "--listen") {
            auto colon = v->rfind(':');
            int port = -1;
            try {
                if (colon != std::string::npos)
                    port = std::stoi(v->substr(colon + 1));
            } catch (...) {
            }
            if (colon == std::string::npos || port < 0 || port > 65535) {
                std::fprintf(stderr, "hysar serve: --listen: expected HOST:PORT, got '%s'\n",
                             v->c_str());
                return 2;
            }
            info.host = v->substr(0, colon);
            info.port = uint16_t(port);
        }
    }
    scene::Scene s;
    if (scene_path) {
        auto r = scene::load_scene_file(*scene_path);
        if (!r) {
            std::fprintf(stderr, "hysar serve: %s\n", r.error().message.c_str());
            return 1;
        }
        s = std::move(r).value();
    } else {
        s = scene::default_scene();
    }
    if (token_file) {
        std::ifstream in(*token_file);
        std::getline(in, info.token);
        if (!in && info.token.empty()) {
            std::fprintf(stderr, "hysar serve: %s: cannot read the token file\n",
                         token_file->c_str());
            return 1;
        }
        if (info.token.empty()) {
            std::fprintf(stderr, "hysar serve: %s: the token file's first line is empty\n",
                         token_file->c_str());
            return 1;
        }
    } else {
        info.token = random_token();
        std::printf("token: %s\n", info.token.c_str());
    }
    auto device = gpu::Device::create(di);
    if (!device) {
        std::fprintf(stderr, "hysar serve: %s\n", device.error().message.c_str());
        return 1;
    }
    auto server = stream::Server::create(*device.value(), s, info);
    if (!server) {
        std::fprintf(stderr, "hysar serve: %s\n", server.error().message.c_str());
        return 1;
    }
    std::printf("serving '%s' on %s:%u%s (device: %s)\n", s.name.c_str(), info.host.c_str(),
                server.value()->port(),
                info.unix_path.empty() ? "" : (" and " + info.unix_path).c_str(),
                device.value()->name().c_str());
    std::fflush(stdout);
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);
    std::signal(SIGPIPE, SIG_IGN);
    stream::Server& srv = *server.value();
    std::thread watcher([&] {
        while (!g_stop.load()) std::this_thread::sleep_for(std::chrono::milliseconds(50));
        srv.stop();
    });
    srv.run();
    g_stop.store(true);
    watcher.join();
    auto stats = srv.stats();
    if (stats_file)
        std::ofstream(*stats_file) << stats.dump(2) << "\n";
    std::printf("stopped: %llu projector render(s)\n",
                (unsigned long long)stats["projector_renders"].get<uint64_t>());
    for (const char* pass : {"projector", "viewer_vd"}) {
        const auto& c = stats["cost_ms"][pass];
        if (c["frames"].get<uint64_t>() == 0)
            continue;
        const auto& m = c["mean"];
        std::printf("  %-10s %llu frame(s), mean ms: pass %.2f  readback %.2f  encode %.2f\n", pass,
                    (unsigned long long)c["frames"].get<uint64_t>(), m["pass"].get<double>(),
                    m["readback"].get<double>(), m["encode"].get<double>());
    }
    return 0;
}

}  // namespace hs::cli
