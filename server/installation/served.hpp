// Forwarding header: the calibrated server on loopback moved to server/served_installation/
// (library hs_served_installation). Kept only so that the files that still include
// "installation/served.hpp" build; remove it once they include "served_installation/served.hpp".
#pragma once

#include "served_installation/served.hpp"
