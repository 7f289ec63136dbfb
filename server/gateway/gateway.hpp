// The gateway of several render nodes (docs/CLUSTER.md): the HAProxy configuration that puts
// them behind one address, and what a node tells HAProxy's agent-check about its load. Pure
// functions; no sockets, no HAProxy, no files.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/result.hpp"

namespace hs::cluster {

struct GatewayNode {
    std::string id;           // HAProxy's server name: [A-Za-z0-9_.-]{1,32}
    std::string host;         // address or name; an IPv6 address without brackets
    uint16_t port = 7700;     // its `hysar serve --listen` port
    uint16_t agent_port = 0;  // its `hysar serve --agent-port`
};

struct GatewayOptions {
    std::string listen_host = "0.0.0.0";
    uint16_t listen_port = 7700;
    std::vector<GatewayNode> nodes;  // the first is the projector's active node, the rest backups
    // HAProxy's runtime API socket (`show stat`, `set server`); empty: none.
    std::string admin_socket;
    uint32_t inspect_ms = 5000;  // how long a connection may take to send its Hello's first bytes
    // TLS at the gateway: a PEM holding the certificate chain and its key (HAProxy's `crt`);
    // clients connect with --tls, HAProxy reads the Hello inside TLS, the nodes behind it speak
    // plain. Empty: plain.
    std::string tls_pem;
    uint32_t agent_inter_ms = 1000;
};

// "ID=HOST:PORT[,agent=PORT]" as `hysar cluster config --node` takes it ("[::1]:7701" for IPv6);
// without agent=, `default_agent_port`.
Result<GatewayNode> parse_node(const std::string& text, uint16_t default_agent_port);

// A complete haproxy.cfg: mode tcp; the frontend waits for the first 17 bytes, accepts only a
// HySAR Hello (magic, type 1) and sends role 1 (projector) to the projector backend (the first
// node active, the others backup) and every other role to the render nodes with leastconn; each
// server checked by TCP connect on its agent port and by agent-check (weight, drain, down), its
// sessions shut when it is marked down. Refuses no nodes, repeated ids or endpoints.
Result<std::string> haproxy_config(const GatewayOptions& options);

// What a node's agent port answers (HAProxy agent-check): a line.
struct NodeLoad {
    bool stopping = false;  // shutting down: "down"
    bool draining = false;  // an operator's drain (the drain file exists): "drain"
    uint64_t sessions = 0;  // authenticated sessions
    uint64_t max_sessions = 1;
    double render_busy = 0;  // the render thread's busy share of the last interval, [0, 1]
};
// "down\n", "drain\n" (drained, or no room for one more session), or "ready up NN%\n" with
// NN = round(100 * (1 - render_busy)) clamped to [10, 100]: a busy node gets fewer new headsets
// from leastconn, never none while it has room; "ready" lifts a drain reported before.
std::string agent_reply(const NodeLoad& load);

}  // namespace hs::cluster
