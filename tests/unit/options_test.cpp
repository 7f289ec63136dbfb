// cli/options.hpp: what every program's option reader accepts and how it refuses.
#include "cli/options.hpp"

#include <gtest/gtest.h>

namespace {

using hs::options::Parsed;
using hs::options::Spec;

const Spec kSpec{{"--scene", "--angles", "--retries"}, {"--window", "--json"}};

Parsed ok(const std::vector<std::string>& args, const Spec& spec = kSpec) {
    auto r = hs::options::parse(args, spec);
    if (auto* e = std::get_if<std::string>(&r))
        ADD_FAILURE() << "refused: " << *e;
    return std::holds_alternative<Parsed>(r) ? std::get<Parsed>(r) : Parsed{};
}

std::string refused(const std::vector<std::string>& args, const Spec& spec = kSpec) {
    auto r = hs::options::parse(args, spec);
    if (!std::holds_alternative<std::string>(r)) {
        ADD_FAILURE() << "taken";
        return "";
    }
    return std::get<std::string>(r);
}

TEST(Options, ValuesInBothFormsRepeatsAndSwitches) {
    const Parsed p = ok({"--scene", "a.json", "--angles=-40,0,40", "--angles", "-1e3", "--window",
                         "--retries", "-1"});
    EXPECT_EQ(p.values.at("--scene"), std::vector<std::string>{"a.json"});
    EXPECT_EQ(p.values.at("--angles"), (std::vector<std::string>{"-40,0,40", "-1e3"}));
    EXPECT_EQ(p.values.at("--retries"), std::vector<std::string>{"-1"});
    EXPECT_EQ(p.values.at("--window"), std::vector<std::string>{"1"});
    EXPECT_EQ(p.values.count("--json"), 0u);  // not given, not present
    EXPECT_TRUE(p.positionals.empty());
}

TEST(Options, RefusalsNameTheOptionAndSuggestANearOne) {
    EXPECT_EQ(refused({"--scen", "x"}), "unknown option '--scen' (did you mean --scene?)");
    EXPECT_EQ(refused({"--window=1", "--bogus-option"}), "unknown option '--bogus-option'");
    EXPECT_EQ(refused({"--scene"}), "--scene needs a value");
    EXPECT_EQ(refused({"--window", "stray"}), "unexpected argument 'stray'");
}

TEST(Options, PositionalWordsWhereACommandTakesThem) {
    Spec spec = kSpec;
    spec.positionals = true;
    const Parsed p = ok({"scene", "--json", "push", "room.json", "--", "--not-an-option"}, spec);
    EXPECT_EQ(p.positionals,
              (std::vector<std::string>{"scene", "push", "room.json", "--not-an-option"}));
    EXPECT_EQ(p.values.count("--json"), 1u);
}

TEST(Options, PassThroughKeepsTheRestInOrder) {
    const Spec global{{"--log-level"}, {"--version"}, false, true};
    const Parsed p =
        ok({"serve", "--scene", "x.json", "--log-level", "debug", "--angles", "-40", "--version"},
           global);
    EXPECT_EQ(p.positionals,
              (std::vector<std::string>{"serve", "--scene", "x.json", "--angles", "-40"}));
    EXPECT_EQ(p.values.at("--log-level"), std::vector<std::string>{"debug"});
    EXPECT_EQ(p.values.count("--version"), 1u);
    EXPECT_EQ(refused({"render", "--log-level"}, global), "--log-level needs a value");
}

}  // namespace
