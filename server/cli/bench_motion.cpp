// `hysar bench motion`: reads its options and runs hs_motion_bench.
#include "cli/bench_motion.hpp"

#include <cstdio>
#include <sstream>

#include "cli/flags.hpp"
#include "motion_bench/motion_bench.hpp"
#include "options/options.hpp"

namespace hs::cli {

namespace {

constexpr const char* kMotionHelp =
    "usage: hysar bench motion [--traces walk,turn,nod] [--modes none,predict,reproject,both]\n"
    "                          [--seconds S] [--delay-ms MS] [--refresh-hz HZ] [--scale F]\n"
    "                          [--noise-deg D] [--noise-mm MM] [--poses-only]\n"
    "                          [--velocity-noise-dps D] [--velocity-noise-mm-s MM]\n"
    "                          [--overscan-deg D]\n"
    "                          [--plane-nearer-m M] [--reference-frames N]\n"
    "                          [--profile NAME] [--json FILE] [--plot FILE.png] [--quick]\n"
    "\n"
    "  Registration while heads move: a headset through `hysar serve` in-process on loopback\n"
    "  (libhysar-client's session), driven by a head-motion trace sampled by a 500 Hz tracker\n"
    "  with noise, shown on a simulated display clock; each shown frame is compared with the\n"
    "  layer the server renders for the true pose at its photon time. Per trace and mode: the\n"
    "  highlight's error in the profile's pixels and in degrees (p50, p95, max), the image error\n"
    "  over the lit pixels, motion-to-photon latency (p50, p95) and the client's time per\n"
    "  stereo frame (prediction and reprojection).\n"
    "\n"
    "  --traces LIST        walk (a slow walk around the prop), turn (200 deg/s through the\n"
    "                       prop), nod (default all three)\n"
    "  --modes LIST         none, predict (pose predicted to photon time), reproject (the\n"
    "                       newest layer warped to the newest pose), both (default all four)\n"
    "  --seconds S          served per trace and mode (default 8; 2 with --quick)\n"
    "  --delay-ms MS        network delay injected each way (default 0)\n"
    "  --refresh-hz HZ      the display clock (default 60)\n"
    "  --scale F            the profile's resolution served, times F (default 0.5); errors\n"
    "                       are in the profile's own pixels\n"
    "  --noise-deg D        tracker noise per sample, degrees (default 0.05)\n"
    "  --noise-mm MM        tracker noise per sample, millimetres (default 0.5)\n"
    "  --velocity-noise-dps D, --velocity-noise-mm-s MM\n"
    "                       the tracker measures its angular and linear velocities too (an\n"
    "                       inertial unit, as OpenXR's XrSpaceVelocity), with this white noise\n"
    "                       per sample plus a constant bias of a fifth of it, and the client's\n"
    "                       predictor takes them (defaults 0.25 deg/s, 5 mm/s)\n"
    "  --poses-only         the tracker gives poses alone: the predictor differentiates them\n"
    "  --overscan-deg D     reproject and both: the layer is rendered D degrees wider on every\n"
    "                       side than the display and warped back onto it, so that a turn has\n"
    "                       what it brings into view (default 5; 0: none; at most 30)\n"
    "  --plane-nearer-m M   reproject and both: the warp puts a plane facing the eye in place,\n"
    "                       by default the one the server sends with each layer (through\n"
    "                       the prop's centre); this moves it M metres nearer (negative:\n"
    "                       farther; -1..1)\n"
    "  --reference-frames N shown frames compared per row (default 60; 20 with --quick)\n"
    "  --profile NAME       a viewer profile of the default scene (default its first)\n"
    "  --json FILE          {\"traces\": {NAME: {MODE: {\"p50_px\", \"p95_px\", \"max_px\",\n"
    "                       \"m2p_p50_ms\", \"m2p_p95_ms\", \"client_ms\", ...}}}}\n"
    "  --plot FILE.png      the p95 error per trace and mode as a bar chart (and FILE.svg)\n"
    "  --quick              short rows (CI)\n"
    "\n"
    "Example: hysar bench motion --quick --traces turn --json out/motion.json\n";

Result<std::vector<std::string>> words(const Flags& f, const char* flag,
                                       const std::vector<std::string>& known,
                                       const std::vector<std::string>& def) {
    if (!f.has(flag))
        return def;
    std::vector<std::string> out;
    std::stringstream in(f.get(flag, ""));
    for (std::string w; std::getline(in, w, ',');) {
        bool ok = false;
        for (const auto& k : known) ok = ok || k == w;
        if (!ok) {
            std::string list;
            for (const auto& k : known) list += (list.empty() ? "" : ", ") + k;
            return make_error(ErrorCode::kInvalidArgument,
                              std::string(flag) + ": '" + w + "' is not one of " + list);
        }
        out.push_back(w);
    }
    if (out.empty())
        return make_error(ErrorCode::kInvalidArgument, std::string(flag) + " names nothing");
    return out;
}

Result<bench::MotionBenchOptions> parse_motion(const std::vector<std::string>& args) {
    HS_ASSIGN_OR_RETURN(
        Flags f, parse_flags(args,
                             {"--traces", "--modes", "--seconds", "--delay-ms", "--refresh-hz",
                              "--scale", "--noise-deg", "--noise-mm", "--velocity-noise-dps",
                              "--velocity-noise-mm-s", "--overscan-deg", "--plane-nearer-m",
                              "--reference-frames", "--profile", "--json", "--plot"},
                             {"--quick", "--poses-only"}));
    bench::MotionBenchOptions o;
    const std::vector<std::string> traces(std::begin(bench::kMotionTraces),
                                          std::end(bench::kMotionTraces));
    const std::vector<std::string> modes(std::begin(bench::kMotionModes),
                                         std::end(bench::kMotionModes));
    HS_ASSIGN_OR_RETURN(o.traces, words(f, "--traces", traces, o.traces));
    HS_ASSIGN_OR_RETURN(o.modes, words(f, "--modes", modes, o.modes));
    HS_ASSIGN_OR_RETURN(o.seconds, parse_number(f, {"--seconds", 0.5, 600}, o.seconds));
    HS_ASSIGN_OR_RETURN(o.delay_ms, parse_number(f, {"--delay-ms", 0, 500}, o.delay_ms));
    HS_ASSIGN_OR_RETURN(o.refresh_hz, parse_number(f, {"--refresh-hz", 10, 240}, o.refresh_hz));
    HS_ASSIGN_OR_RETURN(o.scale, parse_number(f, {"--scale", 0.05, 1}, o.scale));
    HS_ASSIGN_OR_RETURN(o.noise_deg, parse_number(f, {"--noise-deg", 0, 5}, o.noise_deg));
    HS_ASSIGN_OR_RETURN(o.noise_mm, parse_number(f, {"--noise-mm", 0, 50}, o.noise_mm));
    HS_ASSIGN_OR_RETURN(o.velocity_noise_dps,
                        parse_number(f, {"--velocity-noise-dps", 0, 100}, o.velocity_noise_dps));
    HS_ASSIGN_OR_RETURN(o.velocity_noise_mm_s,
                        parse_number(f, {"--velocity-noise-mm-s", 0, 1000}, o.velocity_noise_mm_s));
    o.tracker_velocity = !f.has("--poses-only");
    if (!o.tracker_velocity && (f.has("--velocity-noise-dps") || f.has("--velocity-noise-mm-s")))
        return make_error(ErrorCode::kInvalidArgument,
                          "--poses-only: the tracker gives no velocities, so their noise "
                          "(--velocity-noise-dps, --velocity-noise-mm-s) does not apply");
    HS_ASSIGN_OR_RETURN(o.overscan_deg, parse_number(f, {"--overscan-deg", 0, 30}, o.overscan_deg));
    HS_ASSIGN_OR_RETURN(o.plane_nearer_m,
                        parse_number(f, {"--plane-nearer-m", -1, 1}, o.plane_nearer_m));
    HS_ASSIGN_OR_RETURN(
        double refs,
        parse_number(f, {"--reference-frames", 1, 10000, NumericFlag::kWhole}, o.reference_frames));
    o.reference_frames = int(refs);
    o.profile = f.get("--profile", "");
    o.json_path = f.get("--json", "");
    o.plot_path = f.get("--plot", "");
    o.quick = f.has("--quick");
    return o;
}

}  // namespace

int bench_motion(const std::vector<std::string>& args) {
    if (options::asks_for_help(args)) {
        std::fputs(kMotionHelp, stdout);
        return 0;
    }
    auto o = parse_motion(args);
    if (!o) {
        std::fprintf(stderr, "hysar bench motion: %s\n", o.error().message.c_str());
        return 2;
    }
    return bench::run_motion_bench(*o);
}

}  // namespace hs::cli
