// A libhysar-client handle that closes itself: the client-library tests' one owner of a client.
#pragma once

#include <memory>

#include "clients/lib/hysar_client.h"

namespace hs::net_test {

struct Closer {
    void operator()(hysar_client* c) const { hysar_client_close(c); }
};
using Client = std::unique_ptr<hysar_client, Closer>;

}  // namespace hs::net_test
