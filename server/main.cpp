// `hysar`: the HySAR render server's command line. The global options (--log-level,
// --log-format, --version) are taken out of the arguments here (options/options.hpp), wherever they
// stand, before a subcommand's own parser sees the rest.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include "cli/commands.hpp"
#include "core/log.hpp"
#include "gpu/device.hpp"
#include "gpu/driver_info.hpp"
#include "hysar_version.hpp"
#include "options/options.hpp"

namespace {
void usage(FILE* f) {
    std::fprintf(
        f,
        "usage: hysar <command> [options]\n"
        "\n"
        "commands:\n"
        "  render   render the projector frame and the VD layers of the Fig. 7 viewpoints,\n"
        "           compare them with the double-precision reference, write a contact sheet\n"
        "  serve    the render server: one projector frame per scene version, VD layers per\n"
        "           headset pose, over the protocol of protocol/PROTOCOL.md\n"
        "  bench    measured costs:\n"
        "    bench encoding     bytes per VD layer and encode/decode ms: raw and sparse tiles,\n"
        "                       none/LZ4/zstd, RGBA8 and RGBA16F\n"
        "    bench accuracy     every quality knob of the VD layer against the reference: error,\n"
        "                       ms, bytes; the motion modes' registration error and client ms\n"
        "    bench serve        the served path (in-process server, N headsets on loopback):\n"
        "                       layers/s, steady latency and a new headset's first layer\n"
        "    bench stability    the hard-case table: the GPU's shading code against the double\n"
        "                       reference per formula and regime\n"
        "  eval     the paper's evaluation:\n"
        "    eval optics        eqs. (5)-(6): maximum intensity and dynamic range (Table 2)\n"
        "    eval resolution    pixels per degree of the projector and the headset (Sec. 4.3)\n"
        "    eval compare       Sec. 5.2 on captures: VD areas, MR1, MR2, Lab differences\n"
        "    eval report        everything of eval on the simulated installation (index.html)\n"
        "  calibrate  calibration of a real installation and captured materials:\n"
        "    calibrate patterns   the Gray-code and colour-chart images a device shows\n"
        "    calibrate decode     camera-to-device look-up table from the Gray-code captures\n"
        "    calibrate invert     device-to-camera map by kernel regression\n"
        "    calibrate colour     colour calibration from the colour-chart captures\n"
        "    calibrate optics     the optical constants serve --calibration needs\n"
        "    calibrate capture    a captured material from the reference object's captures\n"
        "    calibrate simulate   the whole chain on the virtual installation, checked against\n"
        "                         its ground truth\n"
        "  admin    a running server:\n"
        "    admin scene push FILE   check a scene here, send it, wait for its new version\n"
        "    admin stats             a running server's figures (--watch S, --json)\n"
        "    admin viewers           one row per headset: frames, latency, poses, bytes\n"
        "    admin kick VIEWER       close a headset's session and tell it why\n"
        "  cluster  render nodes behind one address:\n"
        "    cluster config     print the HAProxy configuration for the render nodes\n"
        "\n"
        "options of every command (before or after it):\n"
        "  --log-level debug|info|warn|error|off   the lowest level logged (default info)\n"
        "  --log-format text|json   text lines, or one JSON object per line for log shippers\n"
        "  --version                the version, git commit, build type and Vulkan device\n"
        "\n"
        "environment: HYSAR_DEVICE=auto|cpu|gpu picks the Vulkan device, HYSAR_VALIDATION=1\n"
        "turns on the Vulkan validation layer, HYSAR_LOG_LEVEL and HYSAR_LOG_FORMAT are the\n"
        "defaults of --log-level and --log-format (docs/OPERATIONS.md, \"Logs\").\n"
        "\n"
        "example: hysar render --out out/render   (the embedded room, Fig. 7 viewpoints)\n");
}

// What --version prints: the build, then the device the server would use (the same choice:
// HYSAR_DEVICE), or why there is none.
int print_version() {
    std::printf("hysar %s\ncommit: %s\nbuild type: %s\n", HYSAR_VERSION, HYSAR_GIT_COMMIT,
                HYSAR_BUILD_TYPE);
    std::fflush(stdout);
    hs::gpu::DeviceCreateInfo info = hs::gpu::device_info_from_environment();
    info.validation = false;  // the device is only named
    const char* env = std::getenv("HYSAR_DEVICE");
    const std::string choice = env && *env ? env : "auto";
    auto device = hs::gpu::Device::create(info);
    if (!device.ok()) {
        std::printf("vulkan device: none (HYSAR_DEVICE=%s): %s\n", choice.c_str(),
                    device.error().message.c_str());
        return 0;
    }
    std::printf("vulkan device: %s (%s; HYSAR_DEVICE=%s)\nvulkan driver: %s\n",
                device.value()->name().c_str(), device.value()->is_cpu() ? "cpu" : "gpu",
                choice.c_str(), hs::gpu::driver_info(*device.value()).c_str());
    return 0;
}

// The global options taken out of `args`. A bad value or variable is a sentence naming it.
struct GlobalOptions {
    hs::log::Level level = hs::log::Level::kInfo;
    hs::log::Format format = hs::log::Format::kText;
    bool version = false;
};

std::optional<std::string> level_from(const std::string& where, const std::string& v,
                                      GlobalOptions& o) {
    auto l = hs::log::parse_level(v);
    if (!l)
        return where + ": '" + v + "' is not a log level (expected one of " +
               hs::log::level_names() + ")";
    o.level = *l;
    return std::nullopt;
}

std::optional<std::string> format_from(const std::string& where, const std::string& v,
                                       GlobalOptions& o) {
    auto f = hs::log::parse_format(v);
    if (!f)
        return where + ": '" + v + "' is not a log format (expected one of " +
               hs::log::format_names() + ")";
    o.format = *f;
    return std::nullopt;
}

std::optional<std::string> take_global_options(std::vector<std::string>& args, GlobalOptions& o) {
    if (const char* e = std::getenv("HYSAR_LOG_LEVEL"); e && *e)
        if (auto err = level_from("HYSAR_LOG_LEVEL", e, o))
            return err;
    if (const char* e = std::getenv("HYSAR_LOG_FORMAT"); e && *e)
        if (auto err = format_from("HYSAR_LOG_FORMAT", e, o))
            return err;
    // Taken out wherever they stand; the rest, in its order, is the command's.
    auto parsed = hs::options::parse(args, {{"--log-level", "--log-format"},
                                            {"--version"},
                                            /*positionals=*/false,
                                            /*pass_through=*/true});
    if (auto* e = std::get_if<std::string>(&parsed)) {
        if (e->rfind("--log-level needs", 0) == 0)
            return *e + " (" + hs::log::level_names() + ")";
        if (e->rfind("--log-format needs", 0) == 0)
            return *e + " (" + hs::log::format_names() + ")";
        return *e;
    }
    auto& p = std::get<hs::options::Parsed>(parsed);
    o.version = p.values.count("--version") > 0;
    if (auto it = p.values.find("--log-level"); it != p.values.end())
        if (auto err = level_from("--log-level", it->second.back(), o))
            return err;
    if (auto it = p.values.find("--log-format"); it != p.values.end())
        if (auto err = format_from("--log-format", it->second.back(), o))
            return err;
    std::vector<std::string> rest = std::move(p.positionals);
    args = std::move(rest);
    return std::nullopt;
}
}  // namespace

int main(int argc, char** argv) {
    std::vector<std::string> all(argv + 1, argv + argc);
    GlobalOptions global;
    if (auto err = take_global_options(all, global)) {
        std::fprintf(stderr, "hysar: %s\n", err->c_str());
        return 2;
    }
    hs::log::set_level(global.level);
    hs::log::set_format(global.format);
    if (auto err = hs::gpu::check_device_environment()) {
        std::fprintf(stderr, "hysar: %s\n", err->c_str());
        return 2;
    }
    if (global.version)
        return print_version();
    if (all.empty()) {
        usage(stderr);
        return 2;
    }
    std::string cmd = all[0];
    std::vector<std::string> args(all.begin() + 1, all.end());
    hs::log::debug("hysar {} (commit {}, {}): {}", HYSAR_VERSION, HYSAR_GIT_COMMIT,
                   HYSAR_BUILD_TYPE, cmd);
    for (const auto& c : hs::cli::kCommands)
        if (cmd == c.name)
            return c.run(args);
    if (hs::options::asks_for_help({cmd}) || cmd == "help") {
        usage(stdout);
        return 0;
    }
    std::fprintf(stderr, "hysar: unknown command '%s'\n\n", cmd.c_str());
    usage(stderr);
    return 2;
}
