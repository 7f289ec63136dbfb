// `hysar cluster config`: the HAProxy configuration that puts several `hysar serve` render
// nodes behind one address (docs/CLUSTER.md).
#include <cstdio>
#include <fstream>

#include <fmt/format.h>

#include "cli/commands.hpp"
#include "cli/flags.hpp"
#include "gateway/gateway.hpp"
#include "options/options.hpp"

namespace hs::cli {

namespace {

const char* kClusterHelp =
    "usage: hysar cluster config --node ID=HOST:PORT[,agent=PORT] [--node ...]\n"
    "                            [--listen HOST:PORT] [--agent-port PORT]\n"
    "                            [--admin-socket PATH] [--tls-pem FILE] [--out FILE]\n"
    "\n"
    "  Prints a HAProxy configuration (haproxy 2.6, mode tcp) that puts the render nodes behind\n"
    "  one address: it accepts only a HySAR Hello, sends the projector to the first node (the\n"
    "  others stand by) and every headset and admin to the node with the fewest sessions,\n"
    "  weighted by what each node's agent port reports (`hysar serve --agent-port`: up NN%,\n"
    "  drain, down); a node that stops answering is marked down within about 2 s and its\n"
    "  clients reconnect through the gateway to another (docs/CLUSTER.md).\n"
    "\n"
    "  --node ID=HOST:PORT[,agent=PORT]  a render node: its id (A-Z a-z 0-9 _ . -), its\n"
    "                         `hysar serve --listen` address and its --agent-port; repeat per\n"
    "                         node, the first serves the projector\n"
    "  --listen HOST:PORT     the gateway's address (default 0.0.0.0:7700)\n"
    "  --agent-port PORT      the agent port of nodes without ',agent=' (default 7800)\n"
    "  --admin-socket PATH    HAProxy's runtime API socket (show stat, set server ...)\n"
    "  --tls-pem FILE         TLS at the gateway: FILE holds the certificate chain and its key\n"
    "                         (cat tls.pem tls.key); clients connect with --tls, --tls-ca or\n"
    "                         --tls-fingerprint; the nodes behind it speak plain\n"
    "  --out FILE             write the configuration here instead of stdout\n"
    "\n"
    "example: hysar cluster config --node a=10.0.0.11:7700 --node b=10.0.0.12:7700 \\\n"
    "             --out /etc/haproxy/haproxy.cfg && haproxy -c -f /etc/haproxy/haproxy.cfg\n";

int cluster_usage_error(const std::string& message) {
    std::fprintf(stderr, "hysar cluster: %s\n", message.c_str());
    return 2;
}

}  // namespace

int run_cluster(const std::vector<std::string>& args) {
    if (options::asks_for_help(args)) {
        std::fputs(kClusterHelp, stdout);
        return 0;
    }
    auto parsed = options::parse(
        args,
        {{"--node", "--listen", "--agent-port", "--admin-socket", "--tls-pem", "--out"}, {}, true});
    if (auto* e = std::get_if<std::string>(&parsed))
        return cluster_usage_error(*e + " (see hysar cluster --help)");
    const auto& p = std::get<options::Parsed>(parsed);
    if (p.positionals != std::vector<std::string>{"config"})
        return cluster_usage_error(
            "expected the command 'config' (hysar cluster config --node ...)");
    auto value = [&](const std::string& k) {
        auto it = p.values.find(k);
        return it == p.values.end() ? std::string() : it->second.back();
    };
    cluster::GatewayOptions o;
    uint16_t agent_port = 7800;
    if (!value("--agent-port").empty()) {
        auto v = parse_integer("--agent-port", value("--agent-port"), 1, 65535);
        if (!v)
            return cluster_usage_error(v.error().message);
        agent_port = uint16_t(*v);
    }
    if (!value("--listen").empty()) {
        const std::string l = value("--listen");
        const auto colon = l.rfind(':');
        auto port = colon == std::string::npos
                        ? Result<int64_t>(make_error(ErrorCode::kInvalidArgument, ""))
                        : parse_integer("--listen", l.substr(colon + 1), 1, 65535);
        if (!port || colon == 0)
            return cluster_usage_error(
                fmt::format("--listen: '{}' is not HOST:PORT with a port in [1, 65535]", l));
        o.listen_host = l.substr(0, colon);
        if (o.listen_host.size() >= 2 && o.listen_host.front() == '[')
            o.listen_host = o.listen_host.substr(1, o.listen_host.size() - 2);
        o.listen_port = uint16_t(*port);
    }
    o.admin_socket = value("--admin-socket");
    o.tls_pem = value("--tls-pem");
    if (!o.tls_pem.empty() && !std::ifstream(o.tls_pem))
        return cluster_usage_error("--tls-pem " + o.tls_pem + ": cannot read the file");
    if (auto it = p.values.find("--node"); it != p.values.end())
        for (const auto& text : it->second) {
            auto n = cluster::parse_node(text, agent_port);
            if (!n)
                return cluster_usage_error(n.error().message);
            o.nodes.push_back(*n);
        }
    auto config = cluster::haproxy_config(o);
    if (!config)
        return cluster_usage_error(config.error().message);
    const std::string out = value("--out");
    if (out.empty()) {
        std::fputs(config->c_str(), stdout);
        return 0;
    }
    std::ofstream f(out);
    f << *config;
    if (!f) {
        std::fprintf(stderr, "hysar cluster: --out %s: cannot write the file\n", out.c_str());
        return 1;
    }
    std::printf("wrote %s (%zu nodes); check it with: haproxy -c -f %s\n", out.c_str(),
                o.nodes.size(), out.c_str());
    return 0;
}

}  // namespace hs::cli
