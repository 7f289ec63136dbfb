// The `hysar` subcommands. Each returns the process exit code: 0 success, 1 failure, 2 usage.
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

}  // namespace hs::cli
