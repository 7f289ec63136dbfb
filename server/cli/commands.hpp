// The `hysar` commands (server/cli/, the library hs_commands). Each reads its arguments with the
// option reader (options/), without the command's name, and returns the process exit code: 0
// success, 1 failure, 2 usage.
#pragma once

#include <string>
#include <vector>

namespace hs::cli {

int run_render(const std::vector<std::string>& args);
int run_serve(const std::vector<std::string>& args);
int run_bench(const std::vector<std::string>& args);
int run_eval(const std::vector<std::string>& args);
int run_calibrate(const std::vector<std::string>& args);
int run_admin(const std::vector<std::string>& args);
int run_cluster(const std::vector<std::string>& args);

// The table server/main.cpp dispatches from: `hysar NAME ARGS...` runs `run(ARGS)`.
struct Command {
    const char* name;
    int (*run)(const std::vector<std::string>& args);
};
inline constexpr Command kCommands[] = {
    {"render", run_render},       {"serve", run_serve}, {"bench", run_bench},    {"eval", run_eval},
    {"calibrate", run_calibrate}, {"admin", run_admin}, {"cluster", run_cluster}};

}  // namespace hs::cli
