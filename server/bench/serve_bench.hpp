// Forwarding header: `hysar bench serve` moved to server/serve_bench/ (library hs_serve_bench).
// Kept only so that the files that still include "bench/serve_bench.hpp" build; remove it once
// they include "serve_bench/serve_bench.hpp".
#pragma once

#include "serve_bench/serve_bench.hpp"
