#include "gateway/gateway.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <set>

#include <fmt/format.h>

namespace hs::cluster {

namespace {

Result<uint16_t> port_of(const std::string& text, const std::string& what) {
    unsigned v = 0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
    if (ec != std::errc() || end != text.data() + text.size() || v < 1 || v > 65535)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("{}: '{}' is not a port in [1, 65535]", what, text));
    return uint16_t(v);
}

bool valid_id(const std::string& id) {
    return !id.empty() && id.size() <= 32 && std::all_of(id.begin(), id.end(), [](char c) {
        return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' || c == '-';
    });
}

// HOST:PORT as HAProxy reads an address: IPv6 in brackets.
std::string endpoint(const std::string& host, uint16_t port) {
    return host.find(':') != std::string::npos ? fmt::format("[{}]:{}", host, port)
                                               : fmt::format("{}:{}", host, port);
}

}  // namespace

Result<GatewayNode> parse_node(const std::string& text, uint16_t default_agent_port) {
    const std::string where = "--node '" + text + "'";
    const auto eq = text.find('=');
    if (eq == std::string::npos)
        return make_error(ErrorCode::kInvalidArgument,
                          where + ": expected ID=HOST:PORT[,agent=PORT]");
    GatewayNode n;
    n.id = text.substr(0, eq);
    if (!valid_id(n.id))
        return make_error(ErrorCode::kInvalidArgument,
                          where + ": the id must be 1 to 32 of A-Z a-z 0-9 _ . -");
    std::string rest = text.substr(eq + 1);
    n.agent_port = default_agent_port;
    if (const auto comma = rest.find(','); comma != std::string::npos) {
        const std::string opt = rest.substr(comma + 1);
        rest = rest.substr(0, comma);
        if (opt.rfind("agent=", 0) != 0)
            return make_error(ErrorCode::kInvalidArgument,
                              where + ": after the address only ',agent=PORT' may follow");
        HS_ASSIGN_OR_RETURN(n.agent_port, port_of(opt.substr(6), where + " agent"));
    }
    const auto colon = rest.rfind(':');
    if (colon == std::string::npos || colon == 0)
        return make_error(ErrorCode::kInvalidArgument, where + ": expected HOST:PORT after '='");
    n.host = rest.substr(0, colon);
    if (n.host.size() >= 2 && n.host.front() == '[' && n.host.back() == ']')
        n.host = n.host.substr(1, n.host.size() - 2);
    else if (n.host.find(':') != std::string::npos)
        return make_error(ErrorCode::kInvalidArgument,
                          where + ": an IPv6 address goes in brackets: [ADDRESS]:PORT");
    if (n.host.empty() || n.host.find_first_of(" \t#") != std::string::npos)
        return make_error(ErrorCode::kInvalidArgument, where + ": no usable host");
    HS_ASSIGN_OR_RETURN(n.port, port_of(rest.substr(colon + 1), where));
    if (n.agent_port == 0)
        return make_error(ErrorCode::kInvalidArgument,
                          where + ": no agent port (add ',agent=PORT' or give --agent-port)");
    return n;
}

Result<std::string> haproxy_config(const GatewayOptions& o) {
    if (o.nodes.empty())
        return make_error(ErrorCode::kInvalidArgument, "no nodes (give --node at least once)");
    std::set<std::string> ids, endpoints;
    for (const auto& n : o.nodes) {
        if (!ids.insert(n.id).second)
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("node id '{}' given twice", n.id));
        if (!endpoints.insert(endpoint(n.host, n.port)).second)
            return make_error(ErrorCode::kInvalidArgument,
                              fmt::format("{} is given twice", endpoint(n.host, n.port)));
        if (!endpoints.insert(endpoint(n.host, n.agent_port)).second)
            return make_error(
                ErrorCode::kInvalidArgument,
                fmt::format("node '{}': agent port {} is another node's or its own service port",
                            n.id, n.agent_port));
    }
    std::string c;
    auto line = [&c](const std::string& s) { c += s + "\n"; };
    line("# HySAR gateway: one address for every render node (hysar cluster config;");
    line("# docs/CLUSTER.md). Validate with `haproxy -c -f FILE`.");
    line("global");
    line("    maxconn 4096");
    if (!o.admin_socket.empty())
        line(fmt::format("    stats socket {} mode 600 level admin", o.admin_socket));
    line("");
    line("defaults");
    line("    mode tcp");
    line("    timeout connect 3s");
    // Sessions live as long as a visit: the server's own idle timeout (Ping every 20 s) ends
    // dead ones.
    line("    timeout client 1h");
    line("    timeout server 1h");
    line("    timeout check 1s");
    line("    # A connection refused by a node that just died goes to another at once.");
    line("    retries 2");
    line("    option redispatch 1");
    line("");
    line("frontend hysar");
    line(fmt::format("    bind {}{}", endpoint(o.listen_host, o.listen_port),
                     o.tls_pem.empty() ? "" : " ssl crt " + o.tls_pem + " ssl-min-ver TLSv1.2"));
    line(fmt::format("    tcp-request inspect-delay {}ms", o.inspect_ms));
    line("    # A Hello's first 17 bytes: magic \"HYSR\", version, type 1, payload length,");
    line("    # sequence, then the role (1 projector, 2 headset, 3 admin). PROTOCOL.md, Frame.");
    line("    acl hello_bytes req.len ge 17");
    line("    acl hysar_magic req.payload(0,4) -m bin 48595352");
    line("    acl hello_type req.payload(6,2) -m bin 0100");
    line("    acl role_projector req.payload(16,1) -m bin 01");
    line("    tcp-request content accept if hello_bytes hysar_magic hello_type");
    line("    tcp-request content reject if hello_bytes");
    line("    tcp-request content reject if WAIT_END");
    line("    use_backend projector if role_projector");
    line("    default_backend render_nodes");
    auto server = [&](const GatewayNode& n, const char* extra) {
        line(fmt::format(
            "    server {} {} weight 100 check port {} inter {}ms fall 2 rise 2 agent-check "
            "agent-port {} agent-inter {}ms on-marked-down shutdown-sessions{}",
            n.id, endpoint(n.host, n.port), n.agent_port, o.agent_inter_ms, n.agent_port,
            o.agent_inter_ms, extra));
    };
    auto checks = [&] {
        // Health: the agent port answers with its state within `timeout check` (a stopped or
        // hung node does not, though its kernel still accepts the connection).
        line("    option tcp-check");
        line("    tcp-check connect");
        line("    tcp-check expect rstring ^(ready|drain)");
    };
    line("");
    line("backend render_nodes");
    line("    balance leastconn");
    checks();
    for (const auto& n : o.nodes) server(n, "");
    line("");
    line("backend projector");
    line("    # One projector: the first node, the others standing by.");
    checks();
    for (size_t i = 0; i < o.nodes.size(); ++i) server(o.nodes[i], i == 0 ? "" : " backup");
    return c;
}

std::string agent_reply(const NodeLoad& load) {
    if (load.stopping)
        return "down\n";
    if (load.draining || load.sessions >= load.max_sessions)
        return "drain\n";
    const double busy =
        std::isfinite(load.render_busy) ? std::clamp(load.render_busy, 0.0, 1.0) : 1.0;
    const int weight = std::clamp(int(std::lround(100.0 * (1.0 - busy))), 10, 100);
    // "ready" ends a drain the node reported before (HAProxy keeps an agent's drain until then).
    return fmt::format("ready up {}%\n", weight);
}

}  // namespace hs::cluster
