// Forwarding header: plotting moved to server/plot/ (library hs_plot). Kept only so that the
// command files that still include "core/figure.hpp" build; remove it once they include
// "plot/figure.hpp".
#pragma once

#include "plot/figure.hpp"
