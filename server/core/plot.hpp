// Forwarding header: plotting moved to server/plot/ (library hs_plot). Kept only so that the
// command files that still include "core/plot.hpp" build; remove it once they include
// "plot/plot.hpp".
#pragma once

#include "plot/plot.hpp"
