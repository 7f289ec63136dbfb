// `hysar serve`: the render server on a scene, until SIGINT or SIGTERM; SIGHUP reloads the scene.
#include <sys/stat.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <optional>
#include <random>
#include <thread>
#include <tuple>
#include <utility>

#include <fmt/format.h>

#include "admin/admin_server.hpp"
#include "calib/serving.hpp"
#include "cli/commands.hpp"
#include "cli/common.hpp"
#include "cli/flags.hpp"
#include "cluster/scene_bus.hpp"
#include "core/log.hpp"
#include "options/options.hpp"
#include "scene/config.hpp"
#include "stream/server.hpp"

namespace hs::cli {

namespace {

const char* kServeHelp =
    "usage: hysar serve [--scene FILE] [--listen HOST:PORT] [--unix PATH] [--token-file FILE]\n"
    "                   [--admin-token-file FILE] [--asset-root DIR] [--device auto|cpu|gpu]\n"
    "                   [--stats-file FILE] [--calibration DIR [--compensation LIST]]\n"
    "                   [--pipeline-cache FILE]\n"
    "                   [--admin-listen [HOST:]PORT] [--tls-cert FILE --tls-key FILE]\n"
    "                   [--agent-port PORT [--drain-file PATH]]\n"
    "                   [--cluster nats://HOST:PORT --node-id ID [bus credentials...]]\n"
    "                   [limits...]\n"
    "\n"
    "  --scene FILE             scene JSON (default: the embedded experiment-1 room); SIGHUP\n"
    "                           reloads it (a broken file is reported, the running scene stays)\n"
    "  --listen HOST:PORT       TCP address (default 127.0.0.1:7700; 0.0.0.0:PORT for a room)\n"
    "  --unix PATH              also listen on a Unix socket\n"
    "  --token-file FILE        the viewers' token (first line; mode 600 or 640); without it a\n"
    "                           random token is generated and printed\n"
    "  --admin-token-file FILE  the admin role's own token (SceneUpdate); without it no session\n"
    "                           may be admin\n"
    "  --asset-root DIR         files a scene may reference lie inside DIR (default: the scene\n"
    "                           file's folder, or the working directory)\n"
    "  --stats-file FILE        write the final stats JSON here on shutdown\n"
    "  --pipeline-cache FILE    the Vulkan pipeline cache: read at start, written after each\n"
    "                           scene's warm-up, so the next start compiles less; a corrupt or\n"
    "                           foreign file is ignored with a warning (docs/OPERATIONS.md)\n"
    "  --admin-listen [HOST:]PORT  an HTTP endpoint for watching the server: Prometheus text at\n"
    "                           /metrics, a live dashboard at / (docs/OPERATIONS.md); a bare\n"
    "                           port means 127.0.0.1, 0 any free port; every request carries\n"
    "                           the viewers' token ('Authorization: Bearer TOKEN'); HTTPS\n"
    "                           with --tls-cert's certificate; off unless given\n"
    "  --calibration DIR        calibrated output (docs/CALIBRATION.md): DIR holds projector/\n"
    "                           (or projectors/NAME/ for each of several), hmd/ (hysar\n"
    "                           calibrate) and optics.json; every projector frame and\n"
    "                           every VD layer are sent as device drives (an RGBA8 code is the\n"
    "                           value the device is sent, not sRGB); a headset of another size\n"
    "                           than the calibrated one gets an InvalidDisplay error\n"
    "  --compensation LIST      with --calibration: all (default), none, or a comma-separated\n"
    "                           list of falloff, albedo, hmd_alpha, black_levels (docs/OPTICS.md)\n"
    "  --tls-cert FILE          TLS on the TCP address: the PEM certificate (chain); clients\n"
    "                           connect with --tls-ca or --tls-fingerprint (the start-up line\n"
    "                           prints it); the Unix socket stays plain (docs/OPERATIONS.md)\n"
    "  --tls-key FILE           its PEM private key (mode 600 or 640)\n"
    "  --reblend-missing        with several projectors: while one has no projector client,\n"
    "                           blend the others again without it so that they cover what\n"
    "                           they can; back to the full blend when it returns (off: the\n"
    "                           frames stay blended over all of them; docs/OPERATIONS.md)\n"
    "  --agent-port PORT        answer HAProxy's agent-check on this port of the --listen host:\n"
    "                           'ready up NN%' from the render load, 'drain', 'down' (hysar\n"
    "                           cluster config; docs/CLUSTER.md)\n"
    "  --drain-file PATH        with --agent-port: answer 'drain' while PATH exists (touch it\n"
    "                           to send new headsets elsewhere, remove it to take them again)\n"
    "  --cluster nats://HOST:PORT  the scene bus (NATS JetStream): the scene is the bucket's\n"
    "                           key 'scene', its revision the scene version on every node; a\n"
    "                           node starts on the bus's scene (or puts its own when there is\n"
    "                           none), SceneUpdate and SIGHUP write through it (docs/CLUSTER.md)\n"
    "                           (needs --admin-token-file: every scene on the bus is signed\n"
    "                           with it, and a value not so signed is ignored)\n"
    "  --node-id ID             with --cluster: this node's name (heartbeats on node.ID)\n"
    "  bus credentials (never in the URL): --cluster-user USER --cluster-password-file FILE,\n"
    "                           or --cluster-token-file FILE, or --cluster-creds FILE (.creds:\n"
    "                           a user JWT and its nkey seed); TLS to the bus with a tls://\n"
    "                           URL or --cluster-ca FILE (the bus's CA), --cluster-cert FILE\n"
    "                           --cluster-key FILE when it asks for a client certificate;\n"
    "                           --cluster-replicas N: copies of the bucket a NATS cluster\n"
    "                           keeps when this node creates it (default 3 where --cluster\n"
    "                           lists three servers or more, comma-separated, else 1)\n"
    "\n"
    "limits (docs/OPERATIONS.md; every flag's range: docs/LIMITS.md):\n"
    "  --max-sessions N (256)            --max-pending N (32)\n"
    "  --handshake-timeout-ms MS (5000)  --idle-timeout-ms MS (120000, 0: never)\n"
    "  --frame-timeout-ms MS (10000)     --max-eye-pixels N (8388608)\n"
    "  --max-target-mib MIB (2048)       --max-queued-mib MIB (16)\n"
    "  --large-display-pixels N (2097152) --max-triangles N (1048576)\n"
    "  --max-projector-pixels N (16000000)\n"
    "  --max-viewer-hz N (60, 0: none)   --max-batch-viewers N (8)\n"
    "  --encoder-threads N (0: 1 on lavapipe, half the cores up to 8 on a GPU)\n"
    "  --tile-codec lz4|zstd|none (lz4)\n"
    "  --pack-tiles auto|on|off (auto: on a GPU): a compute pass packs each sparse layer's lit\n"
    "                      tiles, so only they are read back and encoded (docs/ARCHITECTURE.md)\n"
    "  --multiview auto|on|off (auto: on a GPU): both eyes of a headset in one pass\n"
    "                      (VK_KHR_multiview), bit for bit the per-eye layers\n"
    "  --headsets-per-pass N (1, at most 4): with multiview, up to N headsets of the same\n"
    "                      display in one pass (2N views, as the device allows), bit for bit\n"
    "                      each headset's own pass\n"
    "  --layer-quality Q (92): JPEG quality 1..100 of lossy-tile layers (headsets that register\n"
    "                      encoding 3; the others get the lossless encoding they ask for)\n"
    "  --headset-mbps X (0: none)  --room-mbps Y (0: none): bit-rate limits of the layers,\n"
    "                      Mbit/s, per headset and for all together (shared evenly among the\n"
    "                      headsets served in the last 2 s); kept by lowering a headset's\n"
    "                      layer quality to 50, then its frame rate, never by queueing\n"
    "                      (docs/OPERATIONS.md, \"Bit-rate limits\")\n"
    "  --planning-threads N (0 on lavapipe, cores - 1 up to 7 on a GPU): threads that plan a\n"
    "                      batch's layers beside the render thread\n"
    "\n"
    "example:\n"
    "  hysar serve --scene room.json --listen 0.0.0.0:7700 --token-file /etc/hysar/token \\\n"
    "              --admin-token-file /etc/hysar/admin-token --calibration /etc/hysar/cal\n";

std::string random_token() {
    std::random_device rd;
    std::string t;
    static const char* hex = "0123456789abcdef";
    for (int i = 0; i < 32; ++i) t += hex[rd() % 16];
    return t;
}

std::atomic<bool> g_stop{false};
std::atomic<bool> g_reload{false};
extern "C" void on_stop_signal(int) {
    g_stop.store(true);
}
extern "C" void on_reload_signal(int) {
    g_reload.store(true);
}

// A secret's file (a token, a TLS private key): a regular file that others may neither read
// nor write.
Result<void> check_secret_file(const std::string& path, const char* flag) {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0 || !S_ISREG(st.st_mode))
        return make_error(ErrorCode::kIo, fmt::format("{} {}: cannot read the file", flag, path));
    if (st.st_mode & (S_IROTH | S_IWOTH))
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("{} {}: others may read or write it (mode {:o}); run "
                                      "`chmod 600 {}`",
                                      flag, path, st.st_mode & 0777, path));
    return {};
}

// The first line of a token file, without trailing whitespace or CR. A file that others may
// read is refused: the token is the installation's only lock.
Result<std::string> read_token_file(const std::string& path, const char* flag) {
    HS_TRY(check_secret_file(path, flag));
    std::ifstream in(path);
    std::string token;
    if (!in || !std::getline(in, token))
        return make_error(ErrorCode::kIo, fmt::format("{} {}: cannot read the file", flag, path));
    while (!token.empty() && std::isspace(static_cast<unsigned char>(token.back())))
        token.pop_back();
    if (token.empty())
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("{} {}: the first line is empty", flag, path));
    return token;
}

// A whole number in [lo, hi] for `flag` (docs/LIMITS.md).
Result<uint64_t> parse_count(const Flags& f, const std::string& flag, uint64_t def, uint64_t lo,
                             uint64_t hi) {
    if (!f.has(flag))
        return def;
    HS_ASSIGN_OR_RETURN(int64_t v, parse_integer(flag, f.get(flag, ""), int64_t(lo), int64_t(hi)));
    return uint64_t(v);
}

// A bit-rate limit in Mbit/s for `flag`: 0 (none) or a number in [0.1, 100000].
Result<double> parse_mbps(const Flags& f, const std::string& flag, double def) {
    if (!f.has(flag))
        return def;
    const std::string text = f.get(flag, "");
    HS_ASSIGN_OR_RETURN(double v, parse_double(flag, text, 0, 100000));
    if (v > 0 && v < 0.1)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("{}: '{}' is below 0.1 Mbit/s, the least a headset's layers "
                                      "can be kept to (0: no limit)",
                                      flag, text));
    return v;
}

Result<void> parse_limits(const Flags& f, stream::ServerLimits& l) {
    constexpr uint64_t kDay = 86400000;
    HS_ASSIGN_OR_RETURN(l.max_sessions, parse_count(f, "--max-sessions", l.max_sessions, 1, 65536));
    HS_ASSIGN_OR_RETURN(l.max_pending, parse_count(f, "--max-pending", l.max_pending, 1, 65536));
    HS_ASSIGN_OR_RETURN(l.handshake_timeout_ms,
                        parse_count(f, "--handshake-timeout-ms", l.handshake_timeout_ms, 10, kDay));
    HS_ASSIGN_OR_RETURN(l.idle_timeout_ms,
                        parse_count(f, "--idle-timeout-ms", l.idle_timeout_ms, 0, kDay));
    HS_ASSIGN_OR_RETURN(l.frame_timeout_ms,
                        parse_count(f, "--frame-timeout-ms", l.frame_timeout_ms, 10, kDay));
    HS_ASSIGN_OR_RETURN(l.max_eye_pixels,
                        parse_count(f, "--max-eye-pixels", l.max_eye_pixels, 1, 8192ull * 8192));
    HS_ASSIGN_OR_RETURN(uint64_t target_mib,
                        parse_count(f, "--max-target-mib", l.max_target_bytes >> 20, 1, 1u << 20));
    l.max_target_bytes = target_mib << 20;
    HS_ASSIGN_OR_RETURN(uint64_t queued_mib,
                        parse_count(f, "--max-queued-mib", l.max_queued_bytes >> 20, 1, 4096));
    l.max_queued_bytes = queued_mib << 20;
    HS_ASSIGN_OR_RETURN(
        l.large_display_pixels,
        parse_count(f, "--large-display-pixels", l.large_display_pixels, 1, 8192ull * 8192));
    HS_ASSIGN_OR_RETURN(l.max_viewer_hz,
                        parse_count(f, "--max-viewer-hz", l.max_viewer_hz, 0, 1000));
    HS_ASSIGN_OR_RETURN(l.max_batch_viewers,
                        parse_count(f, "--max-batch-viewers", l.max_batch_viewers, 1, 1024));
    HS_ASSIGN_OR_RETURN(l.headset_mbps, parse_mbps(f, "--headset-mbps", l.headset_mbps));
    HS_ASSIGN_OR_RETURN(l.room_mbps, parse_mbps(f, "--room-mbps", l.room_mbps));
    HS_ASSIGN_OR_RETURN(l.scene.max_triangles,
                        parse_count(f, "--max-triangles", l.scene.max_triangles, 2, 1ull << 32));
    HS_ASSIGN_OR_RETURN(l.scene.max_projector_pixels,
                        parse_count(f, "--max-projector-pixels", l.scene.max_projector_pixels, 1,
                                    16384ull * 16384));
    return {};
}

Result<void> parse_listen(const std::string& v, stream::ServerCreateInfo& info) {
    // Port 0: any free port (the server prints the one it got).
    const auto colon = v.rfind(':');
    Result<int64_t> port = make_error(ErrorCode::kInvalidArgument, "no port");
    if (colon != std::string::npos)
        port = parse_integer("--listen", v.substr(colon + 1), 0, 65535);
    if (!port)
        return make_error(
            ErrorCode::kInvalidArgument,
            fmt::format("--listen: '{}' is not HOST:PORT with a port in [0, 65535]", v));
    info.host = admin::unbracketed(v.substr(0, colon));
    info.port = uint16_t(*port);
    return {};
}

int usage_error(const std::string& message) {
    std::fprintf(stderr, "hysar serve: %s\n", message.c_str());
    return 2;
}

// A start-up failure past the options (a file, the device, the bus): exit status 1.
int start_error(const std::string& message) {
    std::fprintf(stderr, "hysar serve: %s\n", message.c_str());
    return 1;
}

const std::vector<std::string> kServeFlags{"--scene",
                                           "--listen",
                                           "--unix",
                                           "--token-file",
                                           "--admin-token-file",
                                           "--asset-root",
                                           "--device",
                                           "--stats-file",
                                           "--pipeline-cache",
                                           "--admin-listen",
                                           "--max-sessions",
                                           "--max-pending",
                                           "--handshake-timeout-ms",
                                           "--idle-timeout-ms",
                                           "--frame-timeout-ms",
                                           "--max-eye-pixels",
                                           "--max-target-mib",
                                           "--max-queued-mib",
                                           "--large-display-pixels",
                                           "--max-triangles",
                                           "--max-projector-pixels",
                                           "--max-viewer-hz",
                                           "--max-batch-viewers",
                                           "--headset-mbps",
                                           "--room-mbps",
                                           "--encoder-threads",
                                           "--planning-threads",
                                           "--tile-codec",
                                           "--pack-tiles",
                                           "--multiview",
                                           "--headsets-per-pass",
                                           "--layer-quality",
                                           "--calibration",
                                           "--compensation",
                                           "--tls-cert",
                                           "--tls-key",
                                           "--agent-port",
                                           "--drain-file",
                                           "--cluster",
                                           "--node-id",
                                           "--cluster-user",
                                           "--cluster-password-file",
                                           "--cluster-token-file",
                                           "--cluster-creds",
                                           "--cluster-ca",
                                           "--cluster-cert",
                                           "--cluster-key",
                                           "--cluster-replicas"};

// The scene a server starts on and SIGHUP reloads: --scene's file, or the embedded room.
struct SceneSource {
    std::optional<std::string> path;
    std::filesystem::path asset_root;
    scene::SceneLimits limits;

    Result<scene::Scene> load() const {
        if (!path)
            return scene::default_scene();
        return scene::load_scene_file(*path, asset_root, limits);
    }
    // The scene as the bus stores it: the --scene file's text, or the embedded scene's.
    std::string text() const {
        if (!path)
            return std::string(scene::default_scene_json());
        std::ifstream in(*path, std::ios::binary);
        return {std::istreambuf_iterator<char>(in), {}};
    }
};

// What `hysar serve`'s options ask for, checked: everything the server is made with.
struct ServeSetup {
    stream::ServerCreateInfo info;
    gpu::DeviceCreateInfo device = gpu::device_info_from_environment();
    std::optional<admin::AdminOptions> admin;
    calib::Compensation compensation;
    SceneSource scene;
};

// Who else the server answers: --agent-port, --drain-file, --cluster with --node-id,
// --admin-listen. Returns an exit status when an option is refused (the refusal printed).
std::optional<int> read_network(const Flags& f, ServeSetup& s) {
    stream::ServerCreateInfo& info = s.info;
    if (f.has("--agent-port")) {
        auto a = parse_count(f, "--agent-port", 0, 1, 65535);
        if (!a)
            return usage_error(a.error().message);
        info.agent_port = uint16_t(a.value());
    }
    if (f.has("--drain-file")) {
        if (!f.has("--agent-port"))
            return usage_error("--drain-file goes with --agent-port");
        info.drain_file = f.get("--drain-file", "");
    }
    if (f.has("--cluster") != f.has("--node-id"))
        return usage_error("--cluster and --node-id go together");
    if (const std::string id = f.get("--node-id", "-");
        id.empty() || id.size() > 64 ||
        id.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-") !=
            std::string::npos)
        return usage_error("--node-id: '" + id + "' is not 1 to 64 of A-Z a-z 0-9 _ -");
    if (f.has("--admin-listen")) {
        auto a = admin::parse_admin_listen(f.get("--admin-listen", ""));
        if (!a)
            return usage_error(a.error().message);
        s.admin = admin::AdminOptions{};
        std::tie(s.admin->host, s.admin->port) = a.value();
        // The dashboard shows each headset's latest layers: keep one frame per headset.
        info.keep_latest_layers = true;
    }
    return std::nullopt;
}

// How the server renders and encodes: --tile-codec, the thread counts, --compensation.
std::optional<int> read_engine(const Flags& f, ServeSetup& s) {
    stream::ServerCreateInfo& info = s.info;
    info.reblend_missing = f.has("--reblend-missing");
    if (f.has("--pack-tiles")) {
        const std::string v = f.get("--pack-tiles", "");
        if (v != "auto" && v != "on" && v != "off")
            return usage_error("--pack-tiles: expected auto, on or off, got '" + v + "'");
        info.renderer.pack_tiles = v == "auto" ? -1 : v == "on" ? 1 : 0;
    }
    if (f.has("--multiview")) {
        const std::string v = f.get("--multiview", "");
        if (v != "auto" && v != "on" && v != "off")
            return usage_error("--multiview: expected auto, on or off, got '" + v + "'");
        info.renderer.multiview = v == "auto" ? -1 : v == "on" ? 1 : 0;
    }
    if (f.has("--tile-codec")) {
        const std::string c = f.get("--tile-codec", "");
        if (c == "lz4")
            info.tile_codec = protocol::TileCodec::kLz4;
        else if (c == "zstd")
            info.tile_codec = protocol::TileCodec::kZstd;
        else if (c == "none")
            info.tile_codec = protocol::TileCodec::kNone;
        else
            return usage_error("--tile-codec: expected lz4, zstd or none, got '" + c + "'");
    }
    if (auto q = parse_count(f, "--layer-quality", uint64_t(info.layer_quality), 1, 100); q)
        info.layer_quality = int(q.value());
    else
        return usage_error(q.error().message);
    if (auto n = parse_count(f, "--encoder-threads", info.encoder_threads, 0, 64); n)
        info.encoder_threads = uint32_t(n.value());
    else
        return usage_error(n.error().message);
    if (auto n = parse_count(f, "--headsets-per-pass", info.renderer.headsets_per_pass, 1,
                             gpu::kMaxTargetViews / 2);
        n)
        info.renderer.headsets_per_pass = uint32_t(n.value());
    else
        return usage_error(n.error().message);
    if (f.has("--planning-threads")) {
        if (auto n = parse_count(f, "--planning-threads", 0, 0, 64); n)
            info.renderer.planning_threads = int(n.value());
        else
            return usage_error(n.error().message);
    }
    if (f.has("--compensation")) {
        if (!f.has("--calibration"))
            return usage_error("--compensation applies to calibrated output: give --calibration");
        auto c = calib::parse_compensation(f.get("--compensation", ""));
        if (!c)
            return usage_error(c.error().message);
        s.compensation = c.value();
    }
    return std::nullopt;
}

// Every option of `hysar serve` read and checked, in the order their refusals are reported.
// Returns an exit status when one is refused (the refusal printed).
std::optional<int> read_serve_options(const Flags& f, ServeSetup& s) {
    s.info.unix_path = f.get("--unix", "");
    s.info.pipeline_cache_file = f.get("--pipeline-cache", "");
    if (f.has("--device")) {
        const std::string d = f.get("--device", "");
        auto p = gpu::parse_device_preference(d);
        if (!p)
            return usage_error(fmt::format("--device: '{}' is not auto, cpu or gpu", d));
        s.device.preference = *p;
    }
    if (f.has("--listen"))
        if (auto r = parse_listen(f.get("--listen", ""), s.info); !r)
            return usage_error(r.error().message);
    if (auto r = parse_limits(f, s.info.limits); !r)
        return usage_error(r.error().message);
    if (auto stop = read_network(f, s))
        return stop;
    if (auto stop = read_engine(f, s))
        return stop;
    SceneSource& src = s.scene;
    src.path = f.has("--scene") ? std::optional(f.get("--scene", "")) : std::nullopt;
    src.limits = s.info.limits.scene;
    std::error_code ec;
    src.asset_root = f.has("--asset-root") ? std::filesystem::path(f.get("--asset-root", ""))
                     : src.path            ? std::filesystem::absolute(*src.path, ec).parent_path()
                                           : std::filesystem::current_path(ec);
    s.info.asset_root = src.asset_root;
    if (!std::filesystem::is_directory(src.asset_root, ec))
        return usage_error(
            fmt::format("--asset-root: '{}' is not a directory", src.asset_root.string()));
    return std::nullopt;
}

// --calibration loaded and checked against the scene, into `info`.
std::optional<int> load_calibration(const Flags& f, const ServeSetup& s, const scene::Scene& scene,
                                    stream::ServerCreateInfo& info) {
    if (!f.has("--calibration"))
        return std::nullopt;
    auto cal = calib::load_serving_calibration(f.get("--calibration", ""), s.compensation);
    if (!cal)
        return start_error("--calibration: " + cal.error().message);
    if (auto r = cal->check_scene(scene); !r)
        return start_error("--calibration: " + r.error().message);
    info.calibration = std::make_shared<const calib::ServingCalibration>(std::move(cal).value());
    std::printf("calibrated output: %s; RGBA8 frames and layers carry device drive codes\n",
                info.calibration->summary().c_str());
    return std::nullopt;
}

// The viewers' token (--token-file, or a random one, printed) and the admin role's.
std::optional<int> read_tokens(const Flags& f, stream::ServerCreateInfo& info) {
    if (f.has("--token-file")) {
        auto t = read_token_file(f.get("--token-file", ""), "--token-file");
        if (!t)
            return start_error(t.error().message);
        info.token = t.value();
    } else {
        info.token = random_token();
        std::printf("token: %s\n", info.token.c_str());
    }
    if (f.has("--admin-token-file")) {
        auto t = read_token_file(f.get("--admin-token-file", ""), "--admin-token-file");
        if (!t)
            return start_error(t.error().message);
        info.admin_token = t.value();
    }
    return std::nullopt;
}

// --cluster's URL and the bus credentials, each secret from a file of mode 600 or 640.
Result<cluster::SceneBus::Options> read_bus_options(const Flags& f,
                                                    const stream::ServerCreateInfo& info) {
    cluster::SceneBus::Options o;
    o.url = f.get("--cluster", "");
    o.node_id = f.get("--node-id", "");
    o.admin_token = info.admin_token;
    if (o.admin_token.empty())
        return make_error(ErrorCode::kInvalidArgument,
                          "--cluster needs --admin-token-file: every scene on the bus is signed "
                          "with the admin token, and a value not so signed is ignored");
    if (cluster::SceneBus::redacted(o.url) != o.url)
        return make_error(ErrorCode::kInvalidArgument,
                          "--cluster: credentials in the URL would show in ps and the logs; give "
                          "them with --cluster-user and --cluster-password-file, "
                          "--cluster-token-file or --cluster-creds");
    const int kinds = int(f.has("--cluster-user")) + int(f.has("--cluster-token-file")) +
                      int(f.has("--cluster-creds"));
    if (kinds > 1)
        return make_error(ErrorCode::kInvalidArgument,
                          "--cluster-user, --cluster-token-file and --cluster-creds: give one");
    if (f.has("--cluster-user") != f.has("--cluster-password-file"))
        return make_error(ErrorCode::kInvalidArgument,
                          "--cluster-user and --cluster-password-file go together");
    if (f.has("--cluster-user")) {
        o.user = f.get("--cluster-user", "");
        HS_ASSIGN_OR_RETURN(o.password, read_token_file(f.get("--cluster-password-file", ""),
                                                        "--cluster-password-file"));
    }
    if (f.has("--cluster-token-file")) {
        HS_ASSIGN_OR_RETURN(
            o.token, read_token_file(f.get("--cluster-token-file", ""), "--cluster-token-file"));
    }
    if (f.has("--cluster-creds")) {
        o.creds_file = f.get("--cluster-creds", "");
        HS_TRY(check_secret_file(o.creds_file, "--cluster-creds"));
    }
    if (f.has("--cluster-cert") != f.has("--cluster-key"))
        return make_error(ErrorCode::kInvalidArgument,
                          "--cluster-cert and --cluster-key go together");
    o.tls_ca = f.get("--cluster-ca", "");
    o.tls_cert = f.get("--cluster-cert", "");
    o.tls_key = f.get("--cluster-key", "");
    if (!o.tls_key.empty())
        HS_TRY(check_secret_file(o.tls_key, "--cluster-key"));
    o.tls = o.url.rfind("tls://", 0) == 0 || !o.tls_ca.empty() || !o.tls_cert.empty();
    // Three copies by default where the node is given three servers or more (a NATS cluster
    // that can lose one), else one.
    const bool three = std::count(o.url.begin(), o.url.end(), ',') >= 2;
    HS_ASSIGN_OR_RETURN(const uint64_t replicas,
                        parse_count(f, "--cluster-replicas", three ? 3 : 1, 1, 5));
    o.replicas = int(replicas);
    return o;
}

// The newest signed scene on the bus that this node can serve (the same checks and limits as a
// SceneUpdate), or this node's own scene put there when it holds none. A value that is no scene
// at all is skipped (counted and passed over), never a reason not to start; a scene that only
// this node cannot serve (its assets, limits or calibration) is the cluster's, and this node
// does not start on another.
Result<std::pair<uint64_t, scene::Scene>> bus_scene(
    cluster::SceneBus& bus, const ServeSetup& s, const stream::ServerCreateInfo& info, bool& own,
    cluster::SceneBus::Value& held, std::optional<cluster::SceneBus::Value>& newer) {
    own = false;
    // A key holding no scene (a flood pushed every signed one out of its history, or a signed
    // value that is no scene is on top) is put right by a running node's 2-s check, which puts
    // its scene back on top: waited for (three checks), so that this node joins the cluster's
    // scene instead of putting its own over it.
    const auto wait_end = std::chrono::steady_clock::now() + std::chrono::seconds(6);
    bool said = false;
    for (int attempt = 0; attempt < 3; ++attempt) {
        // A bus that just lost a server may take a few seconds to answer (a new leader).
        auto listed = bus.signed_values();
        for (int i = 0; !listed && i < 30; ++i) {
            std::this_thread::sleep_for(std::chrono::milliseconds(500));
            listed = bus.signed_values();
        }
        HS_ASSIGN_OR_RETURN(auto values, std::move(listed));
        std::optional<std::pair<cluster::SceneBus::Value, std::string>> refused;  // the newest
        for (const auto& v : values) {
            if (v.revision > 0xffffffffu)
                continue;
            auto parsed =
                scene::parse_scene(v.json, fmt::format("the bus's scene version {}", v.revision),
                                   info.asset_root, info.asset_root, info.limits.scene);
            if (parsed && info.calibration)
                if (auto r = info.calibration->check_scene(parsed.value()); !r)
                    parsed = make_error(r.error().code, r.error().message);
            if (parsed) {
                held = v;
                // A newer scene refused here is still the cluster's: the caller holds it and
                // takes its version, as a running node does (its writes then follow it).
                if (refused && refused->first.revision > v.revision)
                    newer = refused->first;
                return std::pair{v.revision, std::move(parsed).value()};
            }
            if (!said) {
                ++bus.counters().invalid_values;
                log::warn("scene bus: version {} cannot be served here ({}); trying an older one",
                          v.revision, parsed.error().message);
            }
            if (!scene::is_scene_document(v.json))
                bus.pass_over(v);
            else if (!refused)
                refused.emplace(v, parsed.error().message);
        }
        if (refused)
            return make_error(ErrorCode::kIo,
                              fmt::format("--cluster: the cluster's scene, version {}, cannot be "
                                          "served here ({}), nor any older one on the bus: this "
                                          "node does not start on another scene",
                                          refused->first.revision, refused->second));
        if (bus.newest_seen() > 0 && std::chrono::steady_clock::now() < wait_end) {
            if (!std::exchange(said, true))
                log::info(
                    "scene bus: the key holds no scene; waiting up to 6 s for a running node to "
                    "put the cluster's scene back");
            std::this_thread::sleep_for(std::chrono::milliseconds(250));
            --attempt;
            continue;
        }
        // None to serve: this node's own scene, if no other node puts one first.
        if (said)
            log::warn(
                "scene bus: no node put a scene back within 6 s: this node puts its own over "
                "the bus's values");
        const auto w = bus.write(0, s.scene.text());
        if (w.error == cluster::BusError::kNone) {
            own = true;
            held = {w.revision, 0, w.deadline_ms, s.scene.text()};
            HS_ASSIGN_OR_RETURN(auto mine, s.scene.load());
            return std::pair{w.revision, std::move(mine)};
        }
        if (w.error != cluster::BusError::kConflict)
            return make_error(ErrorCode::kIo, "--cluster: " + w.message);
    }
    return make_error(ErrorCode::kIo,
                      "--cluster: the bus's scene kept changing while this node started");
}

// What a node started on from the bus: the JSON of the scene it serves, and the cluster's newer
// scene it could not serve, if any (applied once the server runs, so that its version is the
// cluster's; it is held).
struct BusStart {
    std::string json;
    std::optional<cluster::SceneBus::Value> newer;
};

// --cluster: joins the scene bus; the bus's scene wins over `scene`, and with none there yet,
// this node's becomes version 1. Scene updates are then published through it.
std::optional<int> join_cluster(const Flags& f, const ServeSetup& s, scene::Scene& scene,
                                stream::ServerCreateInfo& info,
                                std::unique_ptr<cluster::SceneBus>& bus, BusStart& start) {
    if (!f.has("--cluster"))
        return std::nullopt;
    auto options = read_bus_options(f, info);
    if (!options)
        return options.error().code == ErrorCode::kInvalidArgument
                   ? usage_error(options.error().message)
                   : start_error(options.error().message);
    auto b = cluster::SceneBus::connect(options.value());
    if (!b)
        return start_error(b.error().message);
    bus = std::move(b).value();
    bool own = false;
    cluster::SceneBus::Value held;
    auto current = bus_scene(*bus, s, info, own, held, start.newer);
    if (!current)
        return start_error(current.error().message);
    bus->hold(held);
    start.json = held.json;
    scene = std::move(current->second);
    info.initial_scene_version = uint32_t(current->first);
    if (!own)
        std::printf("cluster: serving the bus's scene '%s' (version %u)%s\n", scene.name.c_str(),
                    info.initial_scene_version,
                    s.scene.path ? "; --scene is used only when the bus has none" : "");
    cluster::SceneBus* b_ptr = bus.get();
    info.publish_scene = [b_ptr](uint32_t applied, const std::string& json) {
        const auto w = b_ptr->write(applied, json);
        return w.error == cluster::BusError::kNone ? std::string() : w.message;
    };
    std::printf("cluster: node '%s' on %s%s, scene version %u\n", options->node_id.c_str(),
                cluster::SceneBus::redacted(options->url).c_str(), options->tls ? " (TLS)" : "",
                info.initial_scene_version);
    return std::nullopt;
}

// --tls-cert and --tls-key, the key a secret's file.
std::optional<int> read_tls(const Flags& f, stream::ServerCreateInfo& info) {
    if (f.has("--tls-cert") != f.has("--tls-key"))
        return usage_error("TLS needs both --tls-cert and --tls-key");
    if (f.has("--tls-key")) {
        if (auto r = check_secret_file(f.get("--tls-key", ""), "--tls-key"); !r)
            return start_error(r.error().message);
        info.tls_cert_file = f.get("--tls-cert", "");
        info.tls_key_file = f.get("--tls-key", "");
    }
    return std::nullopt;
}

// The lines that say where a started server listens.
void print_started(const stream::Server& server, const stream::ServerCreateInfo& info,
                   const scene::Scene& scene, const gpu::Device& device) {
    std::printf("serving '%s' on %s:%u%s (device: %s)%s\n", scene.name.c_str(),
                admin::bracketed(info.host).c_str(), server.port(),
                info.unix_path.empty() ? "" : (" and " + info.unix_path).c_str(),
                device.name().c_str(), info.admin_token.empty() ? "; admin role disabled" : "");
    if (const uint16_t agent = server.agent_port(); agent != 0)
        std::printf("agent-check on %s:%u%s\n", admin::bracketed(info.host).c_str(), agent,
                    info.drain_file.empty()
                        ? ""
                        : (" (drain while " + info.drain_file + " exists)").c_str());
    if (const std::string tls = server.tls_summary(); !tls.empty())
        std::printf("TLS on %s:%u: %s\n", admin::bracketed(info.host).c_str(), server.port(),
                    tls.c_str());
}

// Every node (this one's writes too) applies what the bus's watch delivers (signed, the newest
// of a burst), if newer and following what it applied. A refill of the scene this node applied
// last (the bus was found empty, by a delete or a restart without its store) is that scene
// again: relabelled with the new version, not rebuilt. An admin's write of the same JSON is
// built again (it may be meant to reload a changed glTF or texture). `started` is the JSON
// this node started on.
void watch_bus(cluster::SceneBus& bus, stream::Server& server, std::string started) {
    stream::Server* watched = &server;
    cluster::SceneBus* b = &bus;
    struct Applied {
        std::mutex mutex;
        std::string json;
    };
    auto applied_json = std::make_shared<Applied>();
    applied_json->json = std::move(started);
    bus.watch([watched, b, applied_json](const cluster::SceneBus::Value& v) {
        const uint64_t applied = watched->bus_version();
        if (v.revision > 0xffffffffu || !cluster::SceneBus::newer(v.revision, applied))
            return;
        // The version of the scene this node holds: a relabel (its own refill, say) keeps it.
        const uint64_t held = cluster::SceneBus::content_version(b->held());
        if (cluster::SceneBus::stale_refill(v, held)) {
            ++b->counters().stale_refills;
            log::warn(
                "scene bus: version {} ignored: a refill of version {}, older than the held "
                "{} (two nodes refilled an emptied bus at once); this node puts its own back",
                v.revision, v.of, held);
            return;
        }
        if (!cluster::SceneBus::follows(v, applied)) {
            ++b->counters().replayed_values;
            log::warn(
                "scene bus: version {} ignored: it follows version {}, older than the "
                "applied {} (an old value put again)",
                v.revision, v.base, applied);
            return;
        }
        // Held, even if it cannot be served here: it is the cluster's scene, which this node puts
        // back on a bus that comes back empty or behind. A value that is no scene at all is
        // passed over instead (SceneBus::pass_over): never put back.
        std::lock_guard lock(applied_json->mutex);
        if (v.refill && v.json == applied_json->json) {
            b->hold(v);
            ++b->counters().relabelled;
            watched->relabel_scene_version(uint32_t(v.revision));
            log::info("scene bus: version {} arrived, the scene already applied: relabelled",
                      v.revision);
            return;
        }
        if (auto r = watched->apply_scene_version(v.json, uint32_t(v.revision)); !r) {
            ++b->counters().invalid_values;
            if (scene::is_scene_document(v.json))
                b->hold(v);
            else
                b->pass_over(v);
            log::error("scene bus: version {} cannot be served here: {}; the running scene stays",
                       v.revision, r.error().message);
        } else {
            b->hold(v);
            applied_json->json = v.json;
            log::info("scene bus: version {} arrived", v.revision);
        }
    });
}

// The HTTP endpoint of --admin-listen over the server's snapshot and latest images.
Result<std::unique_ptr<admin::AdminServer>> start_admin(
    admin::AdminOptions options, const std::string& token, const std::string& tls_cert_file,
    const std::string& tls_key_file, stream::Server& server, cluster::SceneBus* bus) {
    options.token = token;
    stream::Server* watched = &server;
    // A server with a certificate serves its admin endpoint over HTTPS with it.
    options.tls_cert_file = tls_cert_file;
    options.tls_key_file = tls_key_file;
    HS_ASSIGN_OR_RETURN(
        auto endpoint,
        admin::AdminServer::start(
            options,
            {[watched] { return watched->snapshot(); },
             [watched](uint32_t viewer, int eye) { return watched->latest_layer(viewer, eye); },
             [watched] { return watched->latest_projector_frame(); },
             bus ? std::function<std::string()>([bus] { return bus->metrics_text(); }) : nullptr}));
    std::printf(
        "admin endpoint on %s://%s:%u/ (metrics at /metrics; the viewers' token "
        "as 'Authorization: Bearer TOKEN', or the page's #token=TOKEN)\n",
        tls_cert_file.empty() ? "http" : "https", admin::bracketed(options.host).c_str(),
        endpoint->port());
    return endpoint;
}

void install_signal_handlers() {
    struct sigaction stop_action {
    }, reload_action{};
    stop_action.sa_handler = on_stop_signal;
    reload_action.sa_handler = on_reload_signal;
    sigemptyset(&stop_action.sa_mask);
    sigemptyset(&reload_action.sa_mask);
    sigaction(SIGINT, &stop_action, nullptr);
    sigaction(SIGTERM, &stop_action, nullptr);
    sigaction(SIGHUP, &reload_action, nullptr);
    std::signal(SIGPIPE, SIG_IGN);
}

// SIGHUP: the scene file again, through the bus in a cluster, else straight to the server.
void reload_scene(stream::Server& srv, cluster::SceneBus* bus, const SceneSource& source) {
    if (!source.path) {
        log::warn("SIGHUP: the server runs the embedded scene; nothing to reload");
    } else if (auto next = source.load(); !next) {
        log::error("SIGHUP: {}; the running scene stays", next.error().message);
    } else if (bus) {
        // A cluster: the file goes through the bus like a SceneUpdate.
        const auto w = bus->write(srv.bus_version(), source.text());
        if (w.error != cluster::BusError::kNone)
            log::error("SIGHUP: {}", w.message);
        else
            log::info("SIGHUP: {} written to the scene bus as version {}", *source.path,
                      w.revision);
    } else if (auto r = srv.update_scene(next.value()); !r) {
        log::error("SIGHUP: {}: {}; the running scene stays", *source.path, r.error().message);
    } else {
        log::info("SIGHUP: reloading {}", *source.path);
    }
}

// The signal watcher's loop, beside Server::run: heartbeats on the bus every 2 s, SIGHUP's
// reloads, and the server stopped on SIGINT or SIGTERM.
void watch_signals(stream::Server& srv, cluster::SceneBus* bus, const SceneSource& source,
                   const std::string& node_id) {
    auto beat = std::chrono::steady_clock::now();
    while (!g_stop.load()) {
        if (bus && std::chrono::steady_clock::now() - beat > std::chrono::seconds(2)) {
            beat = std::chrono::steady_clock::now();
            const auto st = srv.stats();
            bus->heartbeat(
                nlohmann::json{{"node", node_id},
                               {"scene_version", srv.scene_version()},
                               {"port", srv.port()},
                               {"sessions", st.value("sessions", nlohmann::json())},
                               {"viewers", st.value("viewers", nlohmann::json::array()).size()}}
                    .dump());
        }
        if (g_reload.exchange(false))
            reload_scene(srv, bus, source);
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    srv.stop();
}

// The final stats: to --stats-file, and the summary lines.
void report_stats(const nlohmann::json& stats, const Flags& f) {
    if (f.has("--stats-file")) {
        std::ofstream out(f.get("--stats-file", ""));
        out << stats.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
        if (!out)
            std::fprintf(stderr, "hysar serve: cannot write %s\n",
                         f.get("--stats-file", "").c_str());
    }
    std::printf("stopped: %llu projector render(s), %zu viewer(s) served\n",
                (unsigned long long)stats.value("projector_renders", uint64_t(0)),
                stats.value("viewers", nlohmann::json::array()).size());
    const auto& proj = stats["cost_ms"]["projector"];
    if (proj.value("frames", uint64_t(0)) > 0)
        std::printf("  projector  %llu frame(s), mean ms: pass %.2f  readback %.2f  encode %.2f\n",
                    (unsigned long long)proj.value("frames", uint64_t(0)),
                    proj["mean"].value("pass", 0.0), proj["mean"].value("readback", 0.0),
                    proj["mean"].value("encode", 0.0));
    const auto& vd = stats["cost_ms"]["viewer_vd"];
    if (vd.value("frames", uint64_t(0)) > 0)
        std::printf(
            "  viewer VD  %llu layer(s), mean ms: queue %.2f  pass %.2f  encode %.2f  "
            "send %.2f\n",
            (unsigned long long)vd.value("frames", uint64_t(0)), vd["mean"].value("queue", 0.0),
            vd["mean"].value("pass", 0.0), vd["mean"].value("encode", 0.0),
            vd["mean"].value("send", 0.0));
}

// Runs a started server until SIGINT or SIGTERM; the bus and the admin endpoint, which call
// the server, are stopped before it goes.
int serve_until_stopped(stream::Server& srv, std::unique_ptr<cluster::SceneBus> bus,
                        std::unique_ptr<admin::AdminServer> admin_endpoint,
                        const SceneSource& source, const Flags& f) {
    std::fflush(stdout);
    install_signal_handlers();
    std::thread watcher([&] { watch_signals(srv, bus.get(), source, f.get("--node-id", "")); });
    srv.run();
    g_stop.store(true);
    watcher.join();
    // The admin endpoint first: its /metrics reads the bus's counters.
    admin_endpoint.reset();
    bus.reset();
    report_stats(srv.stats(), f);
    return 0;
}

}  // namespace

int run_serve(const std::vector<std::string>& args) {
    if (options::asks_for_help(args)) {
        std::fputs(kServeHelp, stdout);
        return 0;
    }
    auto parsed = parse_flags(args, kServeFlags, {"--reblend-missing"});
    if (!parsed) {
        std::fprintf(stderr, "hysar serve: %s\n\n%s", parsed.error().message.c_str(), kServeHelp);
        return 2;
    }
    const Flags& f = parsed.value();
    ServeSetup setup;
    if (auto stop = read_serve_options(f, setup))
        return *stop;
    stream::ServerCreateInfo& info = setup.info;
    auto s = setup.scene.load();
    if (!s)
        return start_error(s.error().message);
    std::unique_ptr<cluster::SceneBus> bus;
    if (auto stop = load_calibration(f, setup, s.value(), info))
        return *stop;
    if (auto stop = read_tokens(f, info))
        return *stop;
    BusStart bus_start;
    if (auto stop = join_cluster(f, setup, s.value(), info, bus, bus_start))
        return *stop;
    if (auto stop = read_tls(f, info))
        return *stop;
    auto device = gpu::Device::create(setup.device);
    if (!device)
        return start_error(device.error().message);
    auto server = stream::Server::create(*device.value(), s.value(), info);
    if (!server)
        return start_error(server.error().message);
    print_started(*server.value(), info, s.value(), *device.value());
    // The server holds its own copy of the scene, only while it serves it: this one goes, with
    // its meshes and textures, so that a replaced first scene is freed (docs/OPERATIONS.md).
    s.value() = scene::Scene{};
    if (bus) {
        if (const auto& r = bus_start.newer) {
            bus->hold(*r);
            if (auto a = server.value()->apply_scene_version(r->json, uint32_t(r->revision)); !a)
                log::warn(
                    "scene bus: the cluster's scene, version {}, cannot be served here ({}); "
                    "this node serves version {} until a newer one",
                    r->revision, a.error().message, info.initial_scene_version);
        }
        watch_bus(*bus, *server.value(), std::move(bus_start.json));
    }
    std::unique_ptr<admin::AdminServer> admin_endpoint;
    if (setup.admin) {
        auto a = start_admin(*setup.admin, info.token, info.tls_cert_file, info.tls_key_file,
                             *server.value(), bus.get());
        if (!a) {
            bus.reset();  // its threads apply scenes to the server: they stop before it goes
            return start_error(a.error().message);
        }
        admin_endpoint = std::move(a).value();
    }
    return serve_until_stopped(*server.value(), std::move(bus), std::move(admin_endpoint),
                               setup.scene, f);
}

}  // namespace hs::cli
