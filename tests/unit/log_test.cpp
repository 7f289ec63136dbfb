// hs::log (server/core/log.hpp): the line formats, JSON escaping of any bytes, the levels, and
// whole lines from many threads at once.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <chrono>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/log.hpp"

namespace {

using hs::log::Context;
using hs::log::Format;
using hs::log::Level;

// 2023-11-14T22:13:20.123Z
const auto kTime = std::chrono::system_clock::time_point(std::chrono::milliseconds(1700000000123));

std::vector<std::string> lines_of(const std::string& text) {
    std::vector<std::string> out;
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);) out.push_back(line);
    return out;
}

// Restores the process-wide level and format whatever a test does.
class Log : public ::testing::Test {
protected:
    void TearDown() override {
        hs::log::set_level(Level::kInfo);
        hs::log::set_format(Format::kText);
    }
};

TEST_F(Log, TextLineHasUtcTimestampLevelAndMessage) {
    EXPECT_EQ(hs::log::format_line(Format::kText, kTime, Level::kInfo, "listening"),
              "2023-11-14T22:13:20.123Z info  listening");
    EXPECT_EQ(hs::log::format_line(Format::kText, kTime, Level::kError, "x"),
              "2023-11-14T22:13:20.123Z error x");
    // Milliseconds keep their leading zeros; a time before 1970 is still a valid timestamp.
    const auto early = std::chrono::system_clock::time_point(std::chrono::milliseconds(-1));
    EXPECT_EQ(hs::log::format_line(Format::kText, early, Level::kWarn, "m"),
              "1969-12-31T23:59:59.999Z warn  m");
}

TEST_F(Log, SessionLinesNameTheSession) {
    EXPECT_EQ(hs::log::format_line(Format::kText, kTime, Level::kInfo, "error 9: bad pose",
                                   Context{3, "hmd"}),
              "2023-11-14T22:13:20.123Z info  session 3 (hmd): error 9: bad pose");
    EXPECT_EQ(hs::log::format_line(Format::kText, kTime, Level::kInfo, "left", Context{12, ""}),
              "2023-11-14T22:13:20.123Z info  session 12: left");
    const auto j = nlohmann::json::parse(hs::log::format_line(
        Format::kJson, kTime, Level::kWarn, "queued", Context{7, "a \"quoted\" name"}));
    EXPECT_EQ(j.at("ts"), "2023-11-14T22:13:20.123Z");
    EXPECT_EQ(j.at("level"), "warn");
    EXPECT_EQ(j.at("session"), 7);
    EXPECT_EQ(j.at("session_name"), "a \"quoted\" name");
    EXPECT_EQ(j.at("msg"), "queued");
    // A line of no session has no session field.
    const auto plain =
        nlohmann::json::parse(hs::log::format_line(Format::kJson, kTime, Level::kInfo, "m"));
    EXPECT_FALSE(plain.contains("session"));
    EXPECT_EQ(plain.size(), 3u);
}

constexpr char kControls[] = "nul \0 bell \x07 esc \x1b del \x7f";

TEST_F(Log, JsonIsValidForAnyBytes) {
    struct Case {
        std::string in, msg;
    };
    const std::vector<Case> cases = {
        {"plain", "plain"},
        {"quote \" backslash \\ slash /", "quote \" backslash \\ slash /"},
        {"lines\nand\ttabs\r", "lines\nand\ttabs\r"},
        {std::string(kControls, sizeof kControls - 1),
         std::string(kControls, sizeof kControls - 1)},
        {"utf-8: \xc3\xa9 \xe2\x82\xac \xf0\x9f\x98\x80",
         "utf-8: \xc3\xa9 \xe2\x82\xac \xf0\x9f\x98\x80"},
        {"lone \xff byte", "lone \xef\xbf\xbd byte"},
        {"cut \xe2\x82", "cut \xef\xbf\xbd\xef\xbf\xbd"},
        {"overlong \xc0\xaf", "overlong \xef\xbf\xbd\xef\xbf\xbd"},
        {"surrogate \xed\xa0\x80", "surrogate \xef\xbf\xbd\xef\xbf\xbd\xef\xbf\xbd"},
        {"", ""},
    };
    for (const auto& c : cases) {
        const std::string line = hs::log::format_line(Format::kJson, kTime, Level::kInfo, c.in);
        SCOPED_TRACE(line);
        EXPECT_EQ(line.find('\n'), std::string::npos);
        nlohmann::json j;
        ASSERT_NO_THROW(j = nlohmann::json::parse(line));
        EXPECT_EQ(j.at("msg").get<std::string>(), c.msg);
    }
}

TEST_F(Log, LevelAndFormatNames) {
    for (Level l : {Level::kDebug, Level::kInfo, Level::kWarn, Level::kError, Level::kOff})
        EXPECT_EQ(hs::log::parse_level(hs::log::to_string(l)), l);
    for (Format f : {Format::kText, Format::kJson})
        EXPECT_EQ(hs::log::parse_format(hs::log::to_string(f)), f);
    for (const char* bad : {"", "INFO", "warning", "err", "verbose", "inf"})
        EXPECT_FALSE(hs::log::parse_level(bad)) << bad;
    for (const char* bad : {"", "JSON", "xml", "plain"})
        EXPECT_FALSE(hs::log::parse_format(bad)) << bad;
}

TEST_F(Log, LevelsFilterWhatReachesStderr) {
    hs::log::set_level(Level::kWarn);
    testing::internal::CaptureStderr();
    hs::log::debug("debug {}", 1);
    hs::log::info("info {}", 2);
    hs::log::warn("warn {}", 3);
    hs::log::error("error {}", 4);
    auto lines = lines_of(testing::internal::GetCapturedStderr());
    ASSERT_EQ(lines.size(), 2u);
    const std::regex text(
        R"(^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z (warn |error) (warn 3|error 4)$)");
    EXPECT_TRUE(std::regex_match(lines[0], text)) << lines[0];
    EXPECT_TRUE(std::regex_match(lines[1], text)) << lines[1];

    hs::log::set_level(Level::kDebug);
    testing::internal::CaptureStderr();
    hs::log::debug("shown");
    lines = lines_of(testing::internal::GetCapturedStderr());
    ASSERT_EQ(lines.size(), 1u);
    EXPECT_NE(lines[0].find(" debug shown"), std::string::npos) << lines[0];

    hs::log::set_level(Level::kOff);
    testing::internal::CaptureStderr();
    hs::log::error("hidden");
    hs::log::for_session(1).error("hidden");
    EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
}

// Lines written from several threads at once come out whole: each is one JSON object.
TEST_F(Log, ThreadsWriteWholeLines) {
    hs::log::set_format(Format::kJson);
    constexpr int kThreads = 4, kLines = 200;
    testing::internal::CaptureStderr();
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t)
        threads.emplace_back([t] {
            const std::string name = "viewer " + std::to_string(t);
            for (int i = 0; i < kLines; ++i)
                hs::log::for_session(uint64_t(t + 1), name)
                    .info("line {} of \"{}\" {}", i, name, std::string(100, 'x'));
        });
    for (auto& th : threads) th.join();
    const auto lines = lines_of(testing::internal::GetCapturedStderr());
    ASSERT_EQ(lines.size(), size_t(kThreads * kLines));
    std::vector<int> per_session(kThreads + 1, 0);
    for (const auto& line : lines) {
        nlohmann::json j;
        ASSERT_NO_THROW(j = nlohmann::json::parse(line)) << line;
        const int s = j.at("session").get<int>();
        ASSERT_TRUE(s >= 1 && s <= kThreads) << line;
        EXPECT_EQ(j.at("session_name"), "viewer " + std::to_string(s - 1));
        ++per_session[s];
    }
    for (int s = 1; s <= kThreads; ++s) EXPECT_EQ(per_session[s], kLines);
}

}  // namespace
