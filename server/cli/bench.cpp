// `hysar bench`: measured costs, as medians over repeated runs in one process.
//   hysar bench encoding: bytes, encode and decode time of VD layers per encoding and codec.
//   hysar bench accuracy: error against cost of every quality knob (server/bench/accuracy.hpp).
//   hysar bench serve: what the server serves against full-frame baselines
//   (server/serve_bench/serve_bench.hpp).
#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <set>
#include <string>
#include <type_traits>
#include <variant>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "bench/accuracy.hpp"
#include "bench/encoding.hpp"
#include "bench/stability.hpp"
#include "cli/bench_motion.hpp"
#include "cli/commands.hpp"
#include "cli/common.hpp"
#include "cli/flags.hpp"
#include "codec/layer_codec.hpp"
#include "core/log.hpp"
#include "motion_bench/motion_bench.hpp"
#include "options/options.hpp"
#include "plot/figure.hpp"
#include "protocol/tiles.hpp"
#include "render/renderer.hpp"
#include "scene/camera.hpp"
#include "scene/config.hpp"
#include "serve_bench/serve_bench.hpp"

namespace hs::cli {

namespace {

const char* kBenchHelp =
    "usage: hysar bench encoding [--repeats N] [--json FILE] [--qualities 50,70,85,95]\n"
    "                            [--moving-frames N] [--plot FILE.png] [--quick]\n"
    "       hysar bench accuracy [--scene FILE] [--out DIR] [--quick] [--repeats N]\n"
    "       hysar bench serve [--headsets 1,8,32] [--seconds S] [--quick] ... (see --help)\n"
    "       hysar bench motion [--traces walk,turn,nod] [--quick] [--json FILE] ... (see --help)\n"
    "       hysar bench stability [--out DIR] [--no-float64]\n"
    "\n"
    "  accuracy   every quality knob of the VD layer (tessellation, render scale, samples per\n"
    "             pixel, point against area lights, HDR format, layer encoding) against the\n"
    "             double-precision reference: RMSE, mean CIEDE2000, render and encode ms, bytes;\n"
    "             and the motion modes (none, predict, reproject, both) on a short 200 deg/s\n"
    "             head turn: p50 and p95 highlight error in px, client ms per stereo frame;\n"
    "             writes DIR/accuracy.csv, DIR/accuracy.png and .svg (default DIR: out/accuracy)\n"
    "             and prints the table. --quick: a quarter of the resolution, fewer settings\n"
    "  encoding   VD layers of the default scene (HoloLens resolution): every Fig. 7 model and\n"
    "             angle, and a moving headset (N stereo frames at 60 Hz walking around the\n"
    "             prop, default 60): bytes per eye layer, Mbit/s per headset at 60 Hz, encode\n"
    "             and decode ms per eye (one core, medians over N repeats) for raw and sparse\n"
    "             tiles (none, LZ4, zstd; RGBA8 and RGBA16F) and lossy tiles at each quality\n"
    "             (lossy: the server's, Huffman tables fitted to a recent layer; lossy-opt:\n"
    "             fitted to each layer; lossy-std: the standard tables), with mean and max\n"
    "             CIEDE2000 over lit pixels and PSNR against the lossless RGBA8 layer; the\n"
    "             moving headset also coded against its previous layer (delta+lz4,\n"
    "             delta+zstd). --plot FILE.png: bytes against error (and .svg).\n"
    "             --quick: the first model only, 4 moving frames\n"
    "  serve      the served path (an in-process server, N headsets on loopback) against\n"
    "             full-frame baselines of the renderer: stereo layers/s, latency, stage costs;\n"
    "             writes DIR/bench-serve.json, DIR/bench-serve.png and .svg (default\n"
    "             out/bench-serve)\n"
    "  motion     registration while heads move (walk, turn, nod) with and without pose\n"
    "             prediction and late reprojection: highlight error in px and degrees, motion-to-\n"
    "             photon latency, client ms; --json FILE\n"
    "  stability  the hard-case table (docs/STABILITY.md): per formula and regime, the GPU's\n"
    "             shading code against the double reference, max error in relative terms and\n"
    "             ulps for fp32 and the half-float layer, with each regime's tolerance; writes\n"
    "             DIR/stability.csv and DIR/stability.md (default out/stability); exit 1 when a\n"
    "             case is outside its tolerance. --no-float64: the shaders a device without\n"
    "             shaderFloat64 runs\n"
    "\n"
    "examples: hysar bench accuracy --quick\n"
    "          hysar bench serve --headsets 1,8 --seconds 5 --lean-baseline ./lean.sh\n"
    "          hysar bench encoding --repeats 5 --json out/encoding.json\n";

const char* kBenchServeHelp =
    "usage: hysar bench serve [--headsets 1,8,32] [--seconds S] [--profile NAME]\n"
    "                         [--format srgb8|rgba16f] [--encoding tiles|lossy|raw]\n"
    "                         [--scene FILE]\n"
    "                         [--out DIR] [--frames N] [--lean-baseline CMD]\n"
    "                         [--lp-threads N,M] [--encoder-threads N]\n"
    "                         [--max-batch-viewers N] [--planning-threads N]\n"
    "                         [--record-on-render-thread] [--pack-tiles auto|on|off]\n"
    "                         [--multiview auto|on|off] [--headsets-per-pass N]\n"
    "                         [--max-target-mib MIB] [--submissions-in-flight N]\n"
    "                         [--headset-mbps X] [--room-mbps Y] [--layer-quality Q]\n"
    "                         [--overscan-deg D]\n"
    "                         [--quick]\n"
    "\n"
    "  What the server serves against full-frame baselines, in one process and one sitting:\n"
    "  the project's renderer on whole stereo pairs (the scene's tessellation, and its\n"
    "  hemisphere at 64 x 32), then `hysar serve` in-process on loopback with N headsets\n"
    "  (one thread and connection each, poses at 60 Hz on an orbit, continuous mode).\n"
    "  Prints a table, writes DIR/bench-serve.json, DIR/bench-serve.png and .svg.\n"
    "\n"
    "  --headsets LIST      served rows, headsets per row (default 1,8,32)\n"
    "  --seconds S          measured seconds per row (default 10), after a warm-up of 1 s\n"
    "                       or until every headset has had its first stereo layer\n"
    "  --profile NAME       the scene's viewer profile (default its first)\n"
    "  --format, --encoding what the headsets register (default srgb8, tiles; lossy: JPEG\n"
    "                       tiles at the server's quality)\n"
    "  --layer-quality Q    the server's JPEG quality of lossy tiles (as hysar serve; 1..100,\n"
    "                       default 92); the error each quality costs: hysar bench encoding\n"
    "  --overscan-deg D     each headset registers its display D degrees wider on every side,\n"
    "                       as hysar-hmd --reproject does (0..30, default 0: not widened)\n"
    "  --frames N           timed stereo pairs per baseline, after 5 warm-up (default 30)\n"
    "  --out DIR            default out/bench-serve\n"
    "  --lean-baseline CMD  run CMD through the shell first; its lean_stereo_ms=<ms> and\n"
    "                       lean_stereo_per_s=<x> become a row and a ratio column\n"
    "  --encoder-threads N  the server's encoder threads (default as hysar serve: 1 on\n"
    "                       lavapipe, half the cores up to 8 on a GPU)\n"
    "  --max-batch-viewers N  viewers per submission (default 8, as hysar serve)\n"
    "  --max-target-mib MIB  the render-target budget (default 2048, as hysar serve; each\n"
    "                       HoloLens headset takes about 20 MiB)\n"
    "  --submissions-in-flight N  the server's VD submissions on the device at once\n"
    "                       (default 3)\n"
    "  --planning-threads N threads planning a batch's layers (default as hysar serve: 0 on\n"
    "                       lavapipe, cores - 1 up to 7 on a GPU); they record them too\n"
    "  --record-on-render-thread  the planning threads plan only and the render thread\n"
    "                       records every layer (to measure what recording on them buys)\n"
    "  --pack-tiles auto|on|off  the server's --pack-tiles (default auto: on a GPU): a\n"
    "                       compute pass packs the lit tiles, only they are read back\n"
    "  --multiview auto|on|off  the server's --multiview (default auto: on a GPU): both\n"
    "                       eyes of a headset in one pass\n"
    "  --headsets-per-pass N  the server's --headsets-per-pass (default 1): with\n"
    "                       multiview, up to N headsets' eyes in one pass\n"
    "  --headset-mbps X, --room-mbps Y  the server's bit-rate limits, Mbit/s (as hysar\n"
    "                       serve; default 0: none); each row then reports the Mbit/s per\n"
    "                       headset, the layer quality and the frame rate they were kept at\n"
    "  --lp-threads N,M     repeat the served rows in a child process per value, with\n"
    "                       LP_NUM_THREADS set (lavapipe's rasteriser threads)\n"
    "  --quick              headsets 1,2, 1.5 s per row, baselines over 5 pairs: checks that\n"
    "                       the command works, says nothing about speed\n"
    "\n"
    "Example: hysar bench serve --headsets 1,8 --seconds 5 --lean-baseline "
    "../shared/perf/lean-baseline.sh\n";

// A comma-separated list of whole numbers in [lo, hi], at least one; a refusal names `flag`, the
// item and the range.
Result<std::vector<int>> int_list(const std::string& flag, const std::string& text, int lo,
                                  int hi) {
    std::vector<int> out;
    size_t at = 0;
    while (at <= text.size()) {
        const size_t comma = std::min(text.find(',', at), text.size());
        HS_ASSIGN_OR_RETURN(int64_t v, parse_integer(flag, text.substr(at, comma - at), lo, hi));
        out.push_back(int(v));
        at = comma + 1;
    }
    return out;
}

// The arguments of `hysar bench serve` (--child-json is internal: the --lp-threads children).
const std::vector<std::string> kServeValued{"--headsets",
                                            "--seconds",
                                            "--profile",
                                            "--format",
                                            "--encoding",
                                            "--scene",
                                            "--out",
                                            "--lean-baseline",
                                            "--lp-threads",
                                            "--frames",
                                            "--child-json",
                                            "--encoder-threads",
                                            "--planning-threads",
                                            "--max-batch-viewers",
                                            "--max-target-mib",
                                            "--submissions-in-flight",
                                            "--headset-mbps",
                                            "--room-mbps",
                                            "--layer-quality",
                                            "--overscan-deg",
                                            "--pack-tiles",
                                            "--multiview",
                                            "--headsets-per-pass"};

// A whole number in [lo, hi] of `flag`, when it is given, into `field`.
template <typename T>
Result<void> read_count(const Flags& f, const char* flag, int64_t lo, int64_t hi, T& field) {
    if (f.has(flag)) {
        HS_ASSIGN_OR_RETURN(int64_t n, parse_integer(flag, f.get(flag, ""), lo, hi));
        field = static_cast<T>(n);
    }
    return {};
}

// The numbers of `hysar bench serve`: headset counts, time, threads.
Result<void> read_serve_numbers(const Flags& f, bench::ServeBenchOptions& o) {
    if (f.has("--headsets")) {
        HS_ASSIGN_OR_RETURN(o.headsets, int_list("--headsets", f.get("--headsets", ""), 1, 256));
    }
    if (f.has("--seconds")) {
        HS_ASSIGN_OR_RETURN(o.seconds,
                            parse_double("--seconds", f.get("--seconds", ""), 0.1, 3600));
    }
    HS_TRY(read_count(f, "--frames", 1, 10000, o.baseline_frames));
    HS_TRY(read_count(f, "--encoder-threads", 0, 64, o.encoder_threads));
    HS_TRY(read_count(f, "--max-batch-viewers", 1, 1024, o.max_batch_viewers));
    HS_TRY(read_count(f, "--max-target-mib", 1, 1u << 20, o.max_target_mib));
    HS_TRY(read_count(f, "--submissions-in-flight", 1, 16, o.submissions_in_flight));
    HS_TRY(read_count(f, "--planning-threads", 0, 64, o.planning_threads));
    HS_TRY(read_count(f, "--headsets-per-pass", 1, gpu::kMaxTargetViews / 2, o.headsets_per_pass));
    HS_TRY(read_count(f, "--layer-quality", 1, 100, o.layer_quality));
    if (f.has("--overscan-deg")) {
        HS_ASSIGN_OR_RETURN(o.overscan_deg,
                            parse_double("--overscan-deg", f.get("--overscan-deg", ""), 0, 30));
    }
    for (auto [flag, field] :
         {std::pair{"--headset-mbps", &o.headset_mbps}, std::pair{"--room-mbps", &o.room_mbps}}) {
        if (!f.has(flag))
            continue;
        HS_ASSIGN_OR_RETURN(*field, parse_double(flag, f.get(flag, ""), 0, 100000));
        if (*field > 0 && *field < 0.1)
            return make_error(ErrorCode::kInvalidArgument,
                              std::string(flag) + ": '" + f.get(flag, "") +
                                  "' is below 0.1 Mbit/s (0: no limit)");
    }
    if (f.has("--lp-threads")) {
        HS_ASSIGN_OR_RETURN(o.lp_threads,
                            int_list("--lp-threads", f.get("--lp-threads", ""), 1, 256));
    }
    return {};
}

// The words of `hysar bench serve`: the layer format, encoding, and the paths.
Result<void> read_serve_words(const Flags& f, bench::ServeBenchOptions& o) {
    const auto invalid = [](std::string m) {
        return make_error(ErrorCode::kInvalidArgument, std::move(m));
    };
    if (f.has("--format")) {
        const std::string v = f.get("--format", "");
        if (v != "srgb8" && v != "rgba16f")
            return invalid("--format wants srgb8 or rgba16f, got '" + v + "'");
        o.format = v == "srgb8" ? protocol::PixelFormat::kRgba8 : protocol::PixelFormat::kRgba16f;
    }
    if (f.has("--pack-tiles")) {
        const std::string v = f.get("--pack-tiles", "");
        if (v != "auto" && v != "on" && v != "off")
            return invalid("--pack-tiles wants auto, on or off, got '" + v + "'");
        o.pack_tiles = v == "auto" ? -1 : v == "on" ? 1 : 0;
    }
    if (f.has("--multiview")) {
        const std::string v = f.get("--multiview", "");
        if (v != "auto" && v != "on" && v != "off")
            return invalid("--multiview wants auto, on or off, got '" + v + "'");
        o.multiview = v == "auto" ? -1 : v == "on" ? 1 : 0;
    }
    if (f.has("--encoding")) {
        const std::string v = f.get("--encoding", "");
        if (v != "tiles" && v != "raw" && v != "lossy")
            return invalid("--encoding wants tiles, lossy or raw, got '" + v + "'");
        o.encoding = v == "tiles"   ? protocol::Encoding::kSparseTiles
                     : v == "lossy" ? protocol::Encoding::kLossyTiles
                                    : protocol::Encoding::kRaw;
    }
    const std::pair<const char*, std::string*> paths[] = {
        {"--profile", &o.profile},
        {"--scene", &o.scene_path},
        {"--out", &o.out_dir},
        {"--lean-baseline", &o.lean_baseline_command},
        {"--child-json", &o.child_json}};
    for (const auto& [flag, field] : paths) {
        if (!f.has(flag))
            continue;
        *field = f.get(flag, "");
        if (field->empty())
            return invalid(std::string(flag) + " wants a non-empty value");
    }
    return {};
}

// The arguments after `hysar bench serve`; on a bad one, a sentence that names the flag.
Result<bench::ServeBenchOptions> parse_serve_args(const std::vector<std::string>& args) {
    HS_ASSIGN_OR_RETURN(Flags f,
                        parse_flags(args, kServeValued, {"--quick", "--record-on-render-thread"}));
    bench::ServeBenchOptions o;
    // The arguments of an --lp-threads child: these options again, each as "--key value",
    // less those that only the parent acts on.
    for (const auto& [flag, values] : f.values) {
        static const std::set<std::string> parent_only{"--lp-threads", "--lean-baseline",
                                                       "--child-json", "--out"};
        if (parent_only.count(flag))
            continue;
        if (values.empty())
            o.child_args.push_back(flag);
        for (const auto& v : values) o.child_args.insert(o.child_args.end(), {flag, v});
    }
    HS_TRY(read_serve_numbers(f, o));
    HS_TRY(read_serve_words(f, o));
    o.record_on_render_thread = f.has("--record-on-render-thread");
    if (f.has("--quick")) {
        o.quick = true;
        if (!f.has("--headsets"))
            o.headsets = {1, 2};
        if (!f.has("--seconds"))
            o.seconds = 1.5;
        if (!f.has("--frames"))
            o.baseline_frames = 5;
    }
    return o;
}

template <typename F>
double time_ms(F&& f) {
    auto t0 = std::chrono::steady_clock::now();
    f();
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

int bench_encoding(const bench::EncodingBenchOptions& o, const std::string& json_path,
                   const std::string& plot_path) {
    scene::Scene s = scene::default_scene();
    auto device = gpu::Device::create(gpu::device_info_from_environment());
    if (!device) {
        std::fprintf(stderr, "hysar bench: %s\n", device.error().message.c_str());
        return 1;
    }
    auto renderer = render::Renderer::create(*device.value(), s, {});
    if (!renderer) {
        std::fprintf(stderr, "hysar bench: %s\n", renderer.error().message.c_str());
        return 1;
    }
    bench::EncodingBenchOptions opts = o;
    opts.progress = [](const std::string& line) {
        std::fprintf(stderr, "%s\n", line.c_str());
        std::fflush(stderr);
    };
    auto rows = bench::run_encoding_bench(*renderer.value(), s, opts);
    if (!rows) {
        std::fprintf(stderr, "hysar bench: %s\n", rows.error().message.c_str());
        return 1;
    }
    const auto& v = s.viewers.front();
    const auto k = scene::eye_intrinsics(v);
    std::printf("VD layers of %ux%u (%s), %d repeats, device %s\n\n%s", k.width, k.height,
                v.name.c_str(), o.repeats, device.value()->name().c_str(),
                bench::encoding_table(rows.value()).c_str());
    if (!plot_path.empty()) {
        if (auto w = write_figure(plot_path, bench::encoding_plot(rows.value())); !w) {
            std::fprintf(stderr, "hysar bench: %s\n", w.error().message.c_str());
            return 1;
        }
        std::printf("wrote %s (and its .svg)\n", plot_path.c_str());
    }
    if (json_path.empty())
        return 0;
    nlohmann::json js = nlohmann::json::array();
    for (const auto& r : rows.value())
        js.push_back({{"views", r.views},
                      {"format", r.format},
                      {"encoding", r.encoding},
                      {"quality", r.quality},
                      {"layers", r.layers},
                      {"bytes_per_eye_layer", r.bytes_per_layer},
                      {"bytes_per_eye_layer_max", r.bytes_per_layer_max},
                      {"mbit_s_per_headset_60hz", r.mbit_s_60hz},
                      {"encode_ms_per_eye", r.encode_ms},
                      {"decode_ms_per_eye", r.decode_ms},
                      {"de00_mean", r.de00_mean},
                      {"de00_max", r.de00_max},
                      {"psnr_db", r.psnr_db ? nlohmann::json(*r.psnr_db) : nlohmann::json()}});
    std::ofstream f(json_path);
    if (!(f << nlohmann::json{{"viewer", v.name},
                              {"eye_width", k.width},
                              {"eye_height", k.height},
                              {"repeats", o.repeats},
                              {"device", device.value()->name()},
                              {"rows", js}}
                   .dump(2)
            << "\n")) {
        std::fprintf(stderr, "hysar bench: cannot write %s\n", json_path.c_str());
        return 1;
    }
    return 0;
}

int bench_stability(const std::string& out_dir, bool float64) {
    const std::filesystem::path dir(out_dir);
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) {
        std::fprintf(stderr, "hysar bench: cannot create %s: %s\n", out_dir.c_str(),
                     ec.message().c_str());
        return 1;
    }
    gpu::DeviceCreateInfo info = gpu::device_info_from_environment();
    info.float64 = float64;
    auto device = gpu::Device::create(info);
    if (!device) {
        std::fprintf(stderr, "hysar bench: %s\n", device.error().message.c_str());
        return 1;
    }
    const auto regimes = bench::stability_regimes(device.value()->float64());
    auto rows = bench::run_stability(*device.value(), regimes);
    if (!rows) {
        std::fprintf(stderr, "hysar bench: %s\n", rows.error().message.c_str());
        return 1;
    }
    const std::string device_text =
        device.value()->name() +
        (device.value()->float64() ? " (shaderFloat64)" : " (fp32 shaders)");
    for (const auto& [file, text] :
         {std::pair{dir / "stability.csv", bench::stability_csv(rows.value())},
          std::pair{dir / "stability.md", "Device: " + device_text + "\n\n" +
                                              bench::stability_table(rows.value(), true)}}) {
        std::ofstream f(file);
        if (!(f << text)) {
            std::fprintf(stderr, "hysar bench: cannot write %s\n", file.c_str());
            return 1;
        }
    }
    size_t cases = 0, failures = 0;
    for (const auto& r : rows.value()) {
        cases += r.cases;
        failures += r.failures;
    }
    std::printf("device: %s\n%s\n%zu cases in %zu rows, %zu outside tolerance\nwrote %s and %s\n",
                device_text.c_str(), bench::stability_table(rows.value(), false).c_str(), cases,
                rows->size(), failures, (dir / "stability.csv").c_str(),
                (dir / "stability.md").c_str());
    for (const auto& r : rows.value())
        if (r.failures)
            std::printf("  %s, %s: %zu of %zu outside tolerance; %s\n", r.formula.c_str(),
                        r.regime.c_str(), r.failures, r.cases, r.first_failure.c_str());
    return failures ? 1 : 0;
}

int bench_accuracy(const std::string& scene_path, const std::string& out_dir, bool quick,
                   int repeats) {
    scene::Scene s = scene::default_scene();
    if (!scene_path.empty()) {
        auto loaded = scene::load_scene_file(scene_path);
        if (!loaded) {
            std::fprintf(stderr, "hysar bench: %s\n", loaded.error().message.c_str());
            return 1;
        }
        s = std::move(loaded.value());
    }
    std::error_code ec;
    std::filesystem::create_directories(out_dir, ec);
    if (ec) {
        std::fprintf(stderr, "hysar bench: cannot create %s: %s\n", out_dir.c_str(),
                     ec.message().c_str());
        return 1;
    }
    auto device = gpu::Device::create(gpu::device_info_from_environment());
    if (!device) {
        std::fprintf(stderr, "hysar bench: %s\n", device.error().message.c_str());
        return 1;
    }
    bench::AccuracyOptions o;
    o.quick = quick;
    o.repeats = repeats;
    o.progress = [](const std::string& line) {
        std::fprintf(stderr, "%s\n", line.c_str());
        std::fflush(stderr);
    };
    auto rep = bench::run_accuracy(*device.value(), s, o);
    if (!rep) {
        std::fprintf(stderr, "hysar bench: %s\n", rep.error().message.c_str());
        return 1;
    }
    // Prediction and reprojection against time: `hysar bench motion`'s four modes on a short
    // head turn (200 deg/s), one row each.
    bench::MotionBenchOptions mo;
    mo.traces = {"turn"};
    mo.seconds = quick ? 2 : 4;
    mo.reference_frames = quick ? 20 : 40;
    mo.scale = quick ? 0.25 : 0.5;
    auto motion = bench::measure_motion(*device.value(), s, mo, o.progress);
    if (!motion) {
        std::fprintf(stderr, "hysar bench: motion rows: %s\n", motion.error().message.c_str());
        return 1;
    }
    for (const auto& m : motion->rows) {
        bench::AccuracyRow r;
        r.knob = "motion";
        r.setting = m.mode;
        r.reference = "fresh";  // the layer rendered for the true pose at photon time
        r.is_default = m.mode == "none";
        r.p50_px = m.p50_px, r.p95_px = m.p95_px, r.client_ms = m.client_ms;
        rep->rows.push_back(r);
    }
    bench::mark_pareto(rep->rows);
    const std::filesystem::path dir(out_dir);
    std::ofstream csv(dir / "accuracy.csv");
    csv << bench::accuracy_csv(rep.value());
    if (!csv) {
        std::fprintf(stderr, "hysar bench: cannot write %s\n", (dir / "accuracy.csv").c_str());
        return 1;
    }
    if (auto w = write_figure(dir / "accuracy.png", bench::accuracy_plot(rep.value())); !w) {
        std::fprintf(stderr, "hysar bench: %s\n", w.error().message.c_str());
        return 1;
    }
    std::printf("%s\nwrote %s, %s and %s\n", bench::accuracy_table(rep.value()).c_str(),
                (dir / "accuracy.csv").c_str(), (dir / "accuracy.png").c_str(),
                (dir / "accuracy.svg").c_str());
    return 0;
}

int bench_serve(const std::vector<std::string>& args) {
    if (options::asks_for_help(args)) {
        std::fputs(kBenchServeHelp, stdout);
        return 0;
    }
    auto o = parse_serve_args(args);
    if (!o) {
        std::fprintf(stderr, "hysar bench serve: %s\n", o.error().message.c_str());
        return 2;
    }
    return bench::run_serve_bench(*o);
}

// `hysar bench stability|encoding|accuracy`: the options each takes, read, and the run.
int bench_offline(const std::string& name, const std::vector<std::string>& args) {
    Result<Flags> f = make_error(ErrorCode::kInvalidArgument, "");
    if (name == "stability")
        f = parse_flags(args, {"--out"}, {"--no-float64"});
    else if (name == "encoding")
        f = parse_flags(args, {"--repeats", "--json", "--qualities", "--moving-frames", "--plot"},
                        {"--quick"});
    else if (name == "accuracy")
        f = parse_flags(args, {"--repeats", "--scene", "--out"}, {"--quick"});
    else {
        std::fprintf(stderr, "hysar bench: unknown benchmark '%s'\n\n%s", name.c_str(), kBenchHelp);
        return 2;
    }
    if (!f) {
        std::fprintf(stderr, "hysar bench %s: %s\n\n%s", name.c_str(), f.error().message.c_str(),
                     kBenchHelp);
        return 2;
    }
    if (name == "stability")
        return bench_stability(f->get("--out", "out/stability"), !f->has("--no-float64"));
    auto repeats =
        parse_number(*f, {"--repeats", 1, 1000, NumericFlag::kWhole}, name == "accuracy" ? 7 : 5);
    if (!repeats) {
        std::fprintf(stderr, "hysar bench: %s\n", repeats.error().message.c_str());
        return 2;
    }
    if (name == "encoding") {
        bench::EncodingBenchOptions o;
        o.repeats = int(*repeats);
        o.quick = f->has("--quick");
        o.moving_frames = o.quick ? 4 : 60;
        if (f->has("--moving-frames")) {
            auto n = parse_number(*f, {"--moving-frames", 0, 3600, NumericFlag::kWhole}, 60);
            if (!n) {
                std::fprintf(stderr, "hysar bench: %s\n", n.error().message.c_str());
                return 2;
            }
            o.moving_frames = int(*n);
        }
        if (f->has("--qualities")) {
            o.qualities.clear();
            const std::string list = f->get("--qualities", "");
            for (size_t at = 0; at <= list.size();) {
                const size_t comma = std::min(list.find(',', at), list.size());
                int q = 0;
                const auto [end, ec] = std::from_chars(list.data() + at, list.data() + comma, q);
                if (ec != std::errc() || end != list.data() + comma || q < 1 || q > 100) {
                    std::fprintf(stderr,
                                 "hysar bench: --qualities: expected a list of 1..100 such as "
                                 "50,85, got '%s'\n",
                                 list.c_str());
                    return 2;
                }
                o.qualities.push_back(q);
                at = comma + 1;
            }
        }
        return bench_encoding(o, f->get("--json", ""), f->get("--plot", ""));
    }
    return bench_accuracy(f->get("--scene", ""), f->get("--out", "out/accuracy"), f->has("--quick"),
                          int(*repeats));
}

}  // namespace

int run_bench(const std::vector<std::string>& args) {
    if (args.empty() ||
        (args[0] != "serve" && args[0] != "motion" && options::asks_for_help(args))) {
        std::fputs(kBenchHelp, args.empty() ? stderr : stdout);
        return args.empty() ? 2 : 0;
    }
    const std::vector<std::string> rest(args.begin() + 1, args.end());
    if (args[0] == "serve")
        return bench_serve(rest);
    if (args[0] == "motion")
        return bench_motion(rest);
    return bench_offline(args[0], rest);
}

}  // namespace hs::cli
