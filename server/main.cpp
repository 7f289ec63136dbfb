// `hysar`: the HySAR render server's command line.
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "commands.hpp"

namespace {
void usage(FILE* f) {
    std::fprintf(
        f,
        "usage: hysar <command> [options]\n"
        "\n"
        "commands:\n"
        "  render   render the projector frame and the VD layers of the Fig. 7 viewpoints,\n"
        "           compare them with the double-precision reference, write a contact sheet\n"
        "           (hysar render --help)\n"
        "  serve    the render server: one projector frame per scene version, VD layers per\n"
        "           headset pose, over the protocol of protocol/PROTOCOL.md (hysar serve --help)\n"
        "  bench    measured costs: hysar bench encoding (hysar bench --help)\n"
        "  eval     the paper's evaluation: optics (Table 2), resolution, compare (Sec. 5.2 on\n"
        "           captures), report (everything, simulated) (hysar eval --help)\n"
        "  calibrate  calibration of a real installation and captured materials: patterns,\n"
        "           decode, invert, colour, capture; simulate runs the whole chain on a virtual\n"
        "           installation (hysar calibrate --help)\n"
        "  admin    a running server: scene push FILE, stats [--watch S], viewers\n"
        "           (hysar admin --help)\n"
        "\n"
        "environment: HYSAR_DEVICE=auto|cpu|gpu picks the Vulkan device, HYSAR_VALIDATION=1\n"
        "turns on the Vulkan validation layer.\n");
}
}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        usage(stderr);
        return 2;
    }
    std::string cmd = argv[1];
    std::vector<std::string> args(argv + 2, argv + argc);
    if (cmd == "render")
        return hs::cli::run_render(args);
    if (cmd == "serve")
        return hs::cli::run_serve(args);
    if (cmd == "bench")
        return hs::cli::run_bench(args);
    if (cmd == "eval")
        return hs::cli::run_eval(args);
    if (cmd == "calibrate")
        return hs::cli::run_calibrate(args);
    if (cmd == "admin")
        return hs::cli::run_admin(args);
    if (cmd == "--help" || cmd == "-h" || cmd == "help") {
        usage(stdout);
        return 0;
    }
    std::fprintf(stderr, "hysar: unknown command '%s'\n\n", cmd.c_str());
    usage(stderr);
    return 2;
}
