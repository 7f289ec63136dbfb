// Forwarding header: the gateway moved to server/gateway/ (library hs_gateway). Kept only so
// that the files that still include "cluster/gateway.hpp" build; remove it once they include
// "gateway/gateway.hpp".
#pragma once

#include "gateway/gateway.hpp"
