// `hysar bench motion` (server/motion_bench/motion_bench.hpp): its options, read and checked.
#pragma once

#include <string>
#include <vector>

namespace hs::cli {

// The arguments after `hysar bench motion`; the exit status (0 ok, 1 failure, 2 usage).
int bench_motion(const std::vector<std::string>& args);

}  // namespace hs::cli
