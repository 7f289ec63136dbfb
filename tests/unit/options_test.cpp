// options/: what every program's option reader and number reader accept and how they refuse.
#include "options/options.hpp"

#include <gtest/gtest.h>

#include "options/numbers.hpp"

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

TEST(Options, AsksForHelpBeforeTheEndOfOptions) {
    EXPECT_TRUE(hs::options::asks_for_help({"--scene", "x", "--help"}));
    EXPECT_TRUE(hs::options::asks_for_help({"-h", "--bogus"}));
    EXPECT_FALSE(hs::options::asks_for_help({"--", "--help"}));
    EXPECT_FALSE(hs::options::asks_for_help({"--helpme"}));
    EXPECT_TRUE(hs::options::asks({"--token", "t", "--version"}, {"--version"}));
}

template <typename T>
std::string refusal(const std::variant<T, std::string>& v) {
    return std::holds_alternative<std::string>(v) ? std::get<std::string>(v) : "taken";
}

TEST(Numbers, ReadsAllOfTheTextInTheRange) {
    using hs::options::read_number;
    EXPECT_EQ(std::get<double>(read_number("+2.5", 0, 10)), 2.5);
    EXPECT_EQ(std::get<double>(read_number("1e-6", 1e-6, 1e6)), 1e-6);
    EXPECT_EQ(refusal(read_number("1e300", 1e-6, 1e6)), "'1e300' is outside [1e-06, 1e+06]");
    EXPECT_EQ(refusal(read_number("1e999", 0, 1)), "'1e999' is outside [0, 1]");
    EXPECT_EQ(refusal(read_number("nan", 0, 1)), "'nan' is not a finite number in [0, 1]");
    EXPECT_EQ(refusal(read_number("-inf", 0, 1)), "'-inf' is not a finite number in [0, 1]");
    for (const char* bad : {"", " 1", "12abc", "0x10", "+-1", "1,5"})
        EXPECT_EQ(refusal(read_number(bad, 0, 100)),
                  "'" + std::string(bad) + "' is not a number in [0, 100]")
            << bad;
}

TEST(Numbers, WholeNumbersAndLists) {
    using hs::options::read_integer;
    EXPECT_EQ(std::get<int64_t>(read_integer("+65535", 0, 65535)), 65535);
    EXPECT_EQ(refusal(read_integer("70000", 0, 65535)), "'70000' is outside [0, 65535]");
    EXPECT_EQ(refusal(read_integer("99999999999999999999", 2, 4294967296)),
              "'99999999999999999999' is outside [2, 4294967296]");
    EXPECT_EQ(refusal(read_integer("1e3", 1, 65536)), "'1e3' is not a whole number in [1, 65536]");
    EXPECT_EQ(refusal(read_integer("1.5", 0, 9)), "'1.5' is not a whole number in [0, 9]");
    const auto list = hs::options::read_number_list("-40,0,40", -360, 360, 1, 8);
    EXPECT_EQ(std::get<std::vector<double>>(list), (std::vector<double>{-40, 0, 40}));
    EXPECT_EQ(refusal(hs::options::read_number_list("1,,2", 0, 9, 1, 8)),
              "item 2: '' is not a number in [0, 9]");
    EXPECT_EQ(refusal(hs::options::read_number_list("1,2", 0, 9, 3, 3)),
              "expected 3 comma-separated numbers, got 2");
}

}  // namespace
