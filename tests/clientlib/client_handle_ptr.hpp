// A libhysar-client handle that closes itself: the client-library tests' one owner of a client.
#pragma once

#include <memory>

#include "clients/lib/hysar_client.h"

namespace hs::net_test {

struct Closer {
    void operator()(hysar_client* c) const { hysar_client_close(c); }
};
using Client = std::unique_ptr<hysar_client, Closer>;

// A test client's configuration: `address`, `token` and `name` must outlive it; it reconnects
// quickly (50 ms, at most 400 ms apart).
inline hysar_client_config test_client_config(const char* address, const char* token,
                                              const char* name, uint32_t role = HYSAR_ROLE_HMD) {
    hysar_client_config c;
    hysar_client_config_init(&c);
    c.address = address;
    c.token = token;
    c.name = name;
    c.role = role;
    c.reconnect_initial_ms = 50;
    c.reconnect_max_ms = 400;
    return c;
}

}  // namespace hs::net_test
