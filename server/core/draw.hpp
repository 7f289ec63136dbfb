// Forwarding header: plotting moved to server/plot/ (library hs_plot). Kept only so that the
// command files that still include "core/draw.hpp" build; remove it once they include
// "plot/draw.hpp".
#pragma once

#include "plot/draw.hpp"
