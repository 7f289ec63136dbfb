// gateway/gateway.hpp: node parsing, the HAProxy configuration's refusals and content, and the
// agent-check reply (the weight formula). haproxy itself checks the text in
// net.cluster_gateway_haproxy.
#include "gateway/gateway.hpp"

#include <gtest/gtest.h>

#include <limits>

namespace hs::cluster {
namespace {

TEST(Gateway, ParsesNodesAndNamesWhatIsWrong) {
    auto n = parse_node("a=10.0.0.1:7700,agent=7801", 7800);
    ASSERT_TRUE(n.ok()) << n.error().message;
    EXPECT_EQ(n->id, "a");
    EXPECT_EQ(n->host, "10.0.0.1");
    EXPECT_EQ(n->port, 7700);
    EXPECT_EQ(n->agent_port, 7801);
    auto v6 = parse_node("n-2=[::1]:7701", 7800);
    ASSERT_TRUE(v6.ok()) << v6.error().message;
    EXPECT_EQ(v6->host, "::1");
    EXPECT_EQ(v6->agent_port, 7800);
    for (const char* bad : {"10.0.0.1:7700", "a b=h:1", "a=h", "a=h:0", "a=h:70000", "a=::1:7700",
                            "a=h:7700,weight=3", "a=h:7700,agent=0", "=h:1"}) {
        auto r = parse_node(bad, 7800);
        ASSERT_FALSE(r.ok()) << bad;
        EXPECT_NE(r.error().message.find(bad), std::string::npos) << r.error().message;
    }
}

TEST(Gateway, ConfigurationRoutesHellosAndRefusesDuplicates) {
    GatewayOptions o;
    EXPECT_FALSE(haproxy_config(o).ok());  // no nodes
    o.nodes = {{"a", "10.0.0.1", 7700, 7800}, {"b", "::1", 7700, 7800}};
    auto c = haproxy_config(o);
    ASSERT_TRUE(c.ok()) << c.error().message;
    const std::string& t = *c;
    EXPECT_NE(t.find("req.payload(0,4) -m bin 48595352"), std::string::npos);  // "HYSR"
    EXPECT_NE(t.find("req.payload(16,1) -m bin 01"), std::string::npos);       // projector
    EXPECT_NE(t.find("balance leastconn"), std::string::npos);
    EXPECT_NE(t.find("server b [::1]:7700 weight 100 check port 7800"), std::string::npos);
    // The projector's backend: a active, b standing by.
    const auto projector = t.find("backend projector");
    ASSERT_NE(projector, std::string::npos);
    EXPECT_NE(t.find("server b [::1]:7700", projector), std::string::npos);
    EXPECT_NE(t.find("backup", projector), std::string::npos);
    EXPECT_EQ(t.find("server a 10.0.0.1:7700 weight 100 check port 7800 inter 1000ms fall 2 "
                     "rise 2 agent-check agent-port 7800 agent-inter 1000ms "
                     "on-marked-down shutdown-sessions backup"),
              std::string::npos);
    EXPECT_NE(t.find("    bind 0.0.0.0:7700\n"), std::string::npos);  // plain by default
    o.tls_pem = "/etc/hysar/gateway.pem";
    auto tls = haproxy_config(o);
    ASSERT_TRUE(tls.ok());
    EXPECT_NE(tls->find("bind 0.0.0.0:7700 ssl crt /etc/hysar/gateway.pem ssl-min-ver TLSv1.2"),
              std::string::npos);
    o.tls_pem.clear();
    o.nodes.push_back({"a", "10.0.0.3", 7700, 7800});
    EXPECT_FALSE(haproxy_config(o).ok());  // id twice
    o.nodes.back() = {"c", "10.0.0.1", 7700, 7801};
    EXPECT_FALSE(haproxy_config(o).ok());  // a's endpoint twice
    o.nodes.back() = {"c", "10.0.0.3", 7800, 7800};
    EXPECT_FALSE(haproxy_config(o).ok());  // its agent port is its service port
}

TEST(Gateway, AgentReplyFollowsTheLoad) {
    NodeLoad l;
    l.max_sessions = 4;
    EXPECT_EQ(agent_reply(l), "ready up 100%\n");
    l.render_busy = 0.25;
    EXPECT_EQ(agent_reply(l), "ready up 75%\n");
    l.render_busy = 1.0;  // saturated: the floor, never zero while there is room
    EXPECT_EQ(agent_reply(l), "ready up 10%\n");
    l.render_busy = 7.0;  // a measuring hiccup beyond the interval
    EXPECT_EQ(agent_reply(l), "ready up 10%\n");
    l.render_busy = std::numeric_limits<double>::quiet_NaN();
    EXPECT_EQ(agent_reply(l), "ready up 10%\n");
    l.render_busy = -0.5;
    EXPECT_EQ(agent_reply(l), "ready up 100%\n");
    l.sessions = 4;  // full
    EXPECT_EQ(agent_reply(l), "drain\n");
    l.sessions = 1;
    l.draining = true;
    EXPECT_EQ(agent_reply(l), "drain\n");
    l.stopping = true;
    EXPECT_EQ(agent_reply(l), "down\n");
}

}  // namespace
}  // namespace hs::cluster
