// The process's resident set, for the tests that bound memory growth outside the sanitizers.
#pragma once

#include <unistd.h>

#include <cstddef>
#include <fstream>

namespace hs::test {

// The process's resident set, KiB.
inline size_t rss_kib() {
    std::ifstream f("/proc/self/statm");
    size_t pages = 0, resident = 0;
    f >> pages >> resident;
    return resident * size_t(sysconf(_SC_PAGESIZE)) / 1024;
}

}  // namespace hs::test
