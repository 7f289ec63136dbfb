// cluster/scene_bus.hpp against a real nats-server with JetStream, whose URL
// tests/cluster/scene_bus_test.sh passes in HYSAR_TEST_NATS_URL (the test fails without it: it
// is never skipped). Each test uses a bucket of its own.
#include "cluster/scene_bus.hpp"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace hs::cluster {
namespace {

constexpr const char* kAdmin = "the-admin-token";

std::unique_ptr<SceneBus> bus(const std::string& bucket, const std::string& node = "t",
                              const std::string& admin = kAdmin) {
    const char* url = std::getenv("HYSAR_TEST_NATS_URL");
    EXPECT_NE(url, nullptr) << "run through tests/cluster/scene_bus_test.sh";
    if (!url)
        return nullptr;
    SceneBus::Options o;
    o.url = url;
    o.node_id = node;
    o.admin_token = admin;
    o.bucket = bucket;
    auto b = SceneBus::connect(o);
    EXPECT_TRUE(b.ok()) << (b.ok() ? "" : b.error().message);
    return b.ok() ? std::move(b).value() : nullptr;
}

// A counter the refilling thread raises after its write has landed, which the watch may deliver
// to the test first: its value once it reaches `want`, or after 2 s.
uint64_t settled(const std::atomic<uint64_t>& counter, uint64_t want) {
    for (int i = 0; i < 200 && counter.load() < want; ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    return counter.load();
}

// What a node's watch delivered, for a test to wait on and read. Declared before the bus, so
// that it outlives the bus's threads (which may deliver until the bus is destroyed).
struct Seen {
    std::mutex m;
    std::condition_variable cv;
    std::vector<SceneBus::Value> values;

    // The watch's callback; `first` runs before the value is recorded, on the bus's thread.
    std::function<void(const SceneBus::Value&)> callback(
        std::function<void(const SceneBus::Value&)> first = nullptr) {
        return [this, first](const SceneBus::Value& v) {
            if (first)
                first(v);
            std::lock_guard lock(m);
            values.push_back(v);
            cv.notify_all();
        };
    }
    // True once `done` holds of the values delivered so far, within `seconds`.
    bool wait(int seconds, const std::function<bool(const std::vector<SceneBus::Value>&)>& done) {
        std::unique_lock lock(m);
        return cv.wait_for(lock, std::chrono::seconds(seconds), [&] { return done(values); });
    }
    // True once the newest value delivered carries `json`, within `seconds`.
    bool last_is(const std::string& json, int seconds) {
        return wait(seconds, [&](const auto& vs) { return !vs.empty() && vs.back().json == json; });
    }
    std::vector<SceneBus::Value> all() {
        std::lock_guard lock(m);
        return values;
    }
};

TEST(SceneBus, CreateOnceThenCompareAndSet) {
    auto a = bus("cas");
    auto b = bus("cas", "u");
    ASSERT_TRUE(a && b);
    auto empty = a->signed_values();
    ASSERT_TRUE(empty.ok());
    EXPECT_TRUE(empty->empty());
    const BusWrite first = a->write(0, "{\"v\":1}");
    ASSERT_EQ(first.error, BusError::kNone) << first.message;
    // A second node that also found the bucket empty loses the race to create.
    const BusWrite late = b->write(0, "{\"v\":\"other\"}");
    EXPECT_EQ(late.error, BusError::kConflict);
    EXPECT_NE(late.message.find("now version " + std::to_string(first.revision)), std::string::npos)
        << late.message;
    // Two admins on the same applied version: one wins, the other is told the new version.
    const BusWrite win = a->write(first.revision, "{\"v\":2}");
    ASSERT_EQ(win.error, BusError::kNone) << win.message;
    EXPECT_GT(win.revision, first.revision);
    const BusWrite lose = b->write(first.revision, "{\"v\":3}");
    EXPECT_EQ(lose.error, BusError::kConflict);
    EXPECT_NE(lose.message.find("scene changed concurrently, now version " +
                                std::to_string(win.revision)),
              std::string::npos)
        << lose.message;
    auto now = b->signed_values();
    ASSERT_TRUE(now.ok() && !now->empty());
    EXPECT_EQ(now->front().revision, win.revision);
    EXPECT_EQ(now->front().base, first.revision);
    EXPECT_EQ(now->front().json, "{\"v\":2}");
}

TEST(SceneBus, WatchDeliversTheLatestThenEachNewOneInOrder) {
    // Declared before the bus, so that they outlive its threads (which may deliver until
    // it is destroyed).
    std::mutex m;
    std::condition_variable cv;
    std::vector<std::pair<uint64_t, std::string>> seen;
    auto w = bus("watch");
    ASSERT_TRUE(w);
    const BusWrite r1 = w->write(0, "one");
    ASSERT_EQ(r1.error, BusError::kNone) << r1.message;
    const BusWrite r2 = w->write(r1.revision, "two");
    ASSERT_EQ(r2.error, BusError::kNone) << r2.message;
    w->watch([&](const SceneBus::Value& v) {
        std::lock_guard lock(m);
        seen.emplace_back(v.revision, v.json);
        cv.notify_all();
    });
    auto writer = bus("watch", "v");
    ASSERT_TRUE(writer);
    uint64_t last = r2.revision;
    for (int i = 0; i < 5; ++i) {
        const BusWrite r = writer->write(last, "n" + std::to_string(i));
        ASSERT_EQ(r.error, BusError::kNone) << r.message;
        last = r.revision;
    }
    std::unique_lock lock(m);
    ASSERT_TRUE(cv.wait_for(lock, std::chrono::seconds(10),
                            [&] { return !seen.empty() && seen.back().first == last; }))
        << "the watch did not deliver revision " << last;
    // The latest at the start ("two"), then new revisions (a burst as its newest), strictly
    // increasing.
    EXPECT_TRUE(seen.front().second == "two" || seen.front().first > r2.revision)
        << seen.front().second;
    for (size_t i = 1; i < seen.size(); ++i) EXPECT_GT(seen[i].first, seen[i - 1].first);
    EXPECT_EQ(seen.back().second, "n4");
}

TEST(SceneBus, OnlyANewerRevisionIsApplied) {
    EXPECT_TRUE(SceneBus::newer(5, 4));
    EXPECT_FALSE(SceneBus::newer(4, 4));  // the node's own write arriving back, or a repeat
    EXPECT_FALSE(SceneBus::newer(3, 4));  // late or reordered
    EXPECT_EQ(conflict_message(9),
              "scene changed concurrently, now version 9; fetch it and try again");
}

TEST(SceneBus, OnlyAValueSignedWithTheAdminTokenChecks) {
    const std::string v = SceneBus::sign(kAdmin, 7, 1700000000000, "{\"name\":\"x\"}");
    auto ok = SceneBus::verify(kAdmin, v);
    ASSERT_TRUE(ok.ok()) << ok.error().message;
    EXPECT_EQ(ok->base, 7u);
    EXPECT_EQ(ok->deadline_ms, 1700000000000u);
    EXPECT_EQ(ok->json, "{\"name\":\"x\"}");
    std::string later = v;
    later.replace(later.find(" 1700000000000 "), 15, " 1800000000000 ");
    EXPECT_FALSE(SceneBus::verify(kAdmin, later).ok());
    EXPECT_FALSE(SceneBus::verify("another-token", v).ok());
    std::string tampered = v;
    tampered.back() = ' ';
    EXPECT_FALSE(SceneBus::verify(kAdmin, tampered).ok());
    std::string rebased = v;
    rebased.replace(rebased.find(" 7 "), 3, " 8 ");
    EXPECT_FALSE(SceneBus::verify(kAdmin, rebased).ok());
    for (const char* junk : {"{{{", "", "{\"name\":\"x\"}", "hysar-scene 1 7 9 00\n{}"})
        EXPECT_FALSE(SceneBus::verify(kAdmin, junk).ok()) << junk;
    EXPECT_FALSE(ok->refill);
    // A refill is signed as one, with the version it puts back: the flag cannot be added to a
    // write, nor taken off a refill, nor its version changed.
    const std::string r = SceneBus::sign(kAdmin, 7, 1700000000000, "{\"name\":\"x\"}", 6);
    auto refill = SceneBus::verify(kAdmin, r);
    ASSERT_TRUE(refill.ok()) << refill.error().message;
    EXPECT_TRUE(refill->refill);
    EXPECT_EQ(refill->of, 6u);
    EXPECT_EQ(refill->json, "{\"name\":\"x\"}");
    EXPECT_EQ(ok->of, 0u);
    std::string flagged = v;
    flagged.insert(flagged.find('\n'), " refill 6");
    EXPECT_FALSE(SceneBus::verify(kAdmin, flagged).ok());
    std::string unflagged = r;
    unflagged.erase(unflagged.find(" refill"), 9);
    EXPECT_FALSE(SceneBus::verify(kAdmin, unflagged).ok());
    std::string newer_of = r;
    newer_of.replace(newer_of.find(" refill 6"), 9, " refill 9");
    EXPECT_FALSE(SceneBus::verify(kAdmin, newer_of).ok());
    for (const char* of : {" refill", " refill ", " refill x", " refill 0"}) {
        std::string bad = r;
        bad.replace(bad.find(" refill 6"), 9, of);
        EXPECT_FALSE(SceneBus::verify(kAdmin, bad).ok()) << of;
    }
    // A refill of an older version than the node holds is stale; of its own or a newer, not.
    EXPECT_TRUE(SceneBus::stale_refill({9, 7, 0, "", true, 8}, 9));
    EXPECT_FALSE(SceneBus::stale_refill({9, 8, 0, "", true, 9}, 9));
    EXPECT_FALSE(SceneBus::stale_refill({11, 10, 0, "", true, 10}, 9));
    EXPECT_FALSE(SceneBus::stale_refill({9, 7, 0, "", false, 0}, 9));
    // A scene's version survives its relabels: a node that relabelled its own refill of version
    // 8 as revision 9 still holds version 8's scene, so a refill of version 9 is not stale to
    // it, and its next refill puts version 8 back, never 9.
    const SceneBus::Value relabelled{9, 8, 0, "eight", true, 8};
    EXPECT_EQ(SceneBus::content_version(relabelled), 8u);
    EXPECT_FALSE(
        SceneBus::stale_refill({10, 9, 0, "nine", true, 9}, SceneBus::content_version(relabelled)));
    EXPECT_EQ(SceneBus::content_version({9, 8, 0, "nine"}), 9u);
    // The rule: newer, and following the applied version (an old value put again is not).
    EXPECT_TRUE(SceneBus::follows({9, 5, 0, ""}, 5));
    EXPECT_FALSE(SceneBus::follows({9, 3, 0, ""}, 5));
    EXPECT_FALSE(SceneBus::follows({5, 4, 0, ""}, 5));
    EXPECT_EQ(SceneBus::redacted("nats://u:secret@host:4222"), "nats://***@host:4222");
    EXPECT_EQ(SceneBus::redacted("nats://host:4222"), "nats://host:4222");
}

// A writer without the admin token (here: signing with another) changes nothing: its values are
// not delivered, are counted, and a node's next write goes over them.
TEST(SceneBus, AValueWithoutTheAdminCredentialIsIgnored) {
    Seen seen;
    auto node = bus("intruder");
    auto intruder = bus("intruder", "x", "not-the-admin-token");
    ASSERT_TRUE(node && intruder);
    const BusWrite r1 = node->write(0, "one");
    ASSERT_EQ(r1.error, BusError::kNone) << r1.message;
    node->watch(seen.callback());
    uint64_t last = r1.revision;
    for (int i = 0; i < 20; ++i) {
        const BusWrite w = intruder->write(last, "evil");
        ASSERT_EQ(w.error, BusError::kNone) << w.message;
        last = w.revision;
    }
    for (int i = 0; i < 200 && node->counters().unsigned_values.load() < 20; ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    ASSERT_GE(node->counters().unsigned_values.load(), 20u);
    // The node's write (on the version it applied) goes over the unsigned ones.
    const BusWrite r2 = node->write(r1.revision, "two");
    ASSERT_EQ(r2.error, BusError::kNone) << r2.message;
    ASSERT_TRUE(seen.wait(
        10, [&](const auto& vs) { return !vs.empty() && vs.back().revision == r2.revision; }));
    for (const auto& v : seen.all()) EXPECT_NE(v.json, "evil");
    auto values = node->signed_values();
    ASSERT_TRUE(values.ok() && !values->empty());
    EXPECT_EQ(values->front().json, "two");
    EXPECT_NE(node->metrics_text().find("hysar_scene_bus_ignored_values_total{why=\"unsigned\"}"),
              std::string::npos);
}

// Puts `value` on the bucket's key as any NATS client can (plain protocol, no JetStream API):
// what an intruder, or a copy put again, looks like to the nodes. True once the server answered.
// `del`: a delete marker (the KV-Operation header) instead of a value.
bool raw_put(const std::string& bucket, const std::string& value, bool del = false) {
    const char* url = std::getenv("HYSAR_TEST_NATS_URL");
    if (!url)
        return false;
    const std::string u = url;
    const auto colon = u.rfind(':');
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(uint16_t(std::stoi(u.substr(colon + 1))));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (fd < 0 || ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0)
        return false;
    const std::string subject = "$KV." + bucket + ".scene ";
    const std::string header = "NATS/1.0\r\nKV-Operation: DEL\r\n\r\n";
    const std::string msg =
        "CONNECT {\"verbose\":false,\"headers\":true}\r\n" +
        (del ? "HPUB " + subject + std::to_string(header.size()) + " " +
                   std::to_string(header.size()) + "\r\n" + header
             : "PUB " + subject + std::to_string(value.size()) + "\r\n" + value) +
        "\r\nPING\r\n";
    bool ok = ::send(fd, msg.data(), msg.size(), 0) == ssize_t(msg.size());
    std::string in;
    char buf[512];
    while (ok && in.find("PONG") == std::string::npos) {
        const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
        ok = n > 0;
        if (ok)
            in.append(buf, size_t(n));
    }
    ::close(fd);
    return ok;
}

// A copy of a signed value put again within its deadline has the same base as the write: of the
// two, every node takes the first stored, so a node starting then serves the write's revision,
// and the next write (which follows it) is taken, over the copy.
TEST(SceneBus, OfTwoCopiesTheFirstStoredIsTheWrite) {
    auto a = bus("copies");
    ASSERT_TRUE(a);
    const BusWrite w = a->write(0, "one");
    ASSERT_EQ(w.error, BusError::kNone) << w.message;
    ASSERT_GT(w.deadline_ms, 0u);
    // The very bytes the bus stored, put again at once (within the deadline).
    ASSERT_TRUE(raw_put("copies", SceneBus::sign(kAdmin, 0, w.deadline_ms, "one")));
    auto b = bus("copies", "u");
    ASSERT_TRUE(b);
    auto values = b->signed_values();
    ASSERT_TRUE(values.ok()) << values.error().message;
    ASSERT_EQ(values->size(), 2u) << "the copy was not stored";
    EXPECT_EQ(values->front().revision, w.revision);
    EXPECT_EQ((*values)[1].revision, w.revision + 1);
    EXPECT_EQ((*values)[1].base, values->front().base);
    // The copy is no one's write: the next write, following the first, goes over it.
    const BusWrite next = b->write(values->front().revision, "two");
    ASSERT_EQ(next.error, BusError::kNone) << next.message;
    EXPECT_EQ(next.revision, w.revision + 2);
    // A node watching from the start takes "one", then "two", never the copy as a version.
    Seen seen;
    auto c = bus("copies", "c");
    ASSERT_TRUE(c);
    c->watch(seen.callback());
    ASSERT_TRUE(seen.last_is("two", 10));
    EXPECT_EQ(seen.all().back().revision, next.revision);
}

// A burst is coalesced: a slow consumer gets the newest of it, not each one.
TEST(SceneBus, ABurstIsCoalescedToItsNewest) {
    // Declared before the bus, so that they outlive its threads (which may deliver until
    // it is destroyed).
    std::mutex m;
    std::condition_variable cv;
    std::vector<uint64_t> seen;
    auto node = bus("burst");
    auto writer = bus("burst", "w");
    ASSERT_TRUE(node && writer);
    BusWrite last = writer->write(0, "v0");
    ASSERT_EQ(last.error, BusError::kNone) << last.message;
    node->watch([&](const SceneBus::Value& v) {
        std::this_thread::sleep_for(std::chrono::milliseconds(300));  // a slow scene build
        std::lock_guard lock(m);
        seen.push_back(v.revision);
        cv.notify_all();
    });
    for (int i = 1; i <= 100; ++i) {
        last = writer->write(last.revision, "v" + std::to_string(i));
        ASSERT_EQ(last.error, BusError::kNone) << last.message;
    }
    std::unique_lock lock(m);
    ASSERT_TRUE(cv.wait_for(lock, std::chrono::seconds(20),
                            [&] { return !seen.empty() && seen.back() == last.revision; }));
    EXPECT_LT(seen.size(), 50u);
    EXPECT_GT(node->counters().superseded_values.load(), 50u);
}

// TLS to the bus and a token: connects with the bus's CA and the token, not without either.
TEST(SceneBus, TlsAndATokenToTheBus) {
    const char* url = std::getenv("HYSAR_TEST_NATS_TLS_URL");
    const char* ca = std::getenv("HYSAR_TEST_NATS_CA");
    const char* token = std::getenv("HYSAR_TEST_NATS_TOKEN");
    ASSERT_TRUE(url && ca && token) << "run through tests/cluster/scene_bus_test.sh";
    SceneBus::Options o;
    o.url = url;
    o.node_id = "tls";
    o.admin_token = kAdmin;
    o.bucket = "tls";
    o.timeout_ms = 2000;
    o.tls = true;
    o.tls_ca = ca;
    o.token = token;
    auto ok = SceneBus::connect(o);
    ASSERT_TRUE(ok.ok()) << ok.error().message;
    const BusWrite w = ok.value()->write(0, "over tls");
    EXPECT_EQ(w.error, BusError::kNone) << w.message;
    auto no_token = o;
    no_token.token.clear();
    EXPECT_FALSE(SceneBus::connect(no_token).ok());
    auto no_ca = o;
    no_ca.tls_ca.clear();
    auto untrusted = SceneBus::connect(no_ca);
    EXPECT_FALSE(untrusted.ok());
}

TEST(SceneBus, AnUnreachableBusIsNamed) {
    SceneBus::Options o;
    o.url = "nats://127.0.0.1:1";
    o.node_id = "t";
    o.admin_token = kAdmin;
    o.bucket = "x";
    o.timeout_ms = 500;
    auto b = SceneBus::connect(o);
    ASSERT_FALSE(b.ok());
    EXPECT_NE(b.error().message.find("nats://127.0.0.1:1"), std::string::npos) << b.error().message;
}

// Two nodes refilled an emptied bus at once, and the one that held the older version landed at
// the newer's revision: the node that holds the newer version finds that refill on the key,
// puts its own back over it (as the version it holds), and never applies the older scene.
TEST(SceneBus, ARefillOfAnOlderVersionIsPutBackOver) {
    Seen seen;
    auto a = bus("stale");
    ASSERT_TRUE(a);
    const BusWrite one = a->write(0, "one");
    ASSERT_EQ(one.error, BusError::kNone) << one.message;
    const BusWrite two = a->write(one.revision, "two");
    ASSERT_EQ(two.error, BusError::kNone) << two.message;
    a->hold({two.revision, one.revision, two.deadline_ms, "two"});
    a->watch(seen.callback());
    // The lagging node's refill of version one, signed as it signs one, stored past "two".
    const auto now_ms = uint64_t(std::chrono::duration_cast<std::chrono::milliseconds>(
                                     std::chrono::system_clock::now().time_since_epoch())
                                     .count());
    ASSERT_TRUE(
        raw_put("stale", SceneBus::sign(kAdmin, two.revision, now_ms + 5000, "one", one.revision)));
    ASSERT_TRUE(seen.wait(
        15,
        [&](const auto& vs) { return !vs.empty() && vs.back().json == "two" && vs.back().refill; }))
        << "node a did not put version " << two.revision << " back over the stale refill";
    const auto delivered = seen.all();
    EXPECT_EQ(delivered.back().of, two.revision);
    EXPECT_GT(delivered.back().revision, two.revision + 1);
    EXPECT_EQ(settled(a->counters().refills, 1), 1u);
    // What the watch delivered before: the stale refill, which stale_refill() names for the
    // node (serve's watch ignores it), and never as anything but a refill of version one.
    for (const auto& v : delivered) {
        if (v.json == "one" && v.revision > two.revision) {
            EXPECT_TRUE(SceneBus::stale_refill(v, two.revision));
        }
    }
    // The bus now holds "two" on top: a node starting now serves it.
    auto c = bus("stale", "c");
    ASSERT_TRUE(c);
    auto values = c->signed_values();
    ASSERT_TRUE(values.ok()) << values.error().message;
    ASSERT_FALSE(values->empty());
    EXPECT_EQ(values->front().json, "two");
}

// A signed value the bus stored after its write's deadline (the writer was told the write
// failed: the bus was frozen, and stored it when thawed) is taken by no node, counted as late,
// and is not a node's start-up scene either; the next write goes through.
TEST(SceneBus, AValueStoredAfterItsDeadlineIsTakenByNoNode) {
    Seen seen;
    auto a = bus("late");
    ASSERT_TRUE(a);
    const BusWrite one = a->write(0, "one");
    ASSERT_EQ(one.error, BusError::kNone) << one.message;
    a->watch(seen.callback());
    ASSERT_TRUE(seen.last_is("one", 10));
    // Following version one as a write would, signed with a deadline 3 s past: the bus stores
    // it now.
    const auto now_ms = uint64_t(std::chrono::duration_cast<std::chrono::milliseconds>(
                                     std::chrono::system_clock::now().time_since_epoch())
                                     .count());
    ASSERT_TRUE(raw_put("late", SceneBus::sign(kAdmin, one.revision, now_ms - 3000, "late")));
    for (int i = 0; i < 100 && a->counters().late_values.load() == 0; ++i)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    EXPECT_EQ(a->counters().late_values.load(), 1u);
    EXPECT_NE(a->metrics_text().find("hysar_scene_bus_ignored_values_total{why=\"late\"} 1"),
              std::string::npos)
        << a->metrics_text();
    // A node starting now starts on version one, not on the late value.
    auto c = bus("late", "c");
    ASSERT_TRUE(c);
    auto values = c->signed_values();
    ASSERT_TRUE(values.ok()) << values.error().message;
    ASSERT_FALSE(values->empty());
    EXPECT_EQ(values->front().json, "one");
    // The next write (on version one: the late value is no one's) reaches the node.
    const BusWrite two = a->write(one.revision, "two");
    ASSERT_EQ(two.error, BusError::kNone) << two.message;
    ASSERT_TRUE(seen.last_is("two", 10));
    for (const auto& v : seen.all()) EXPECT_NE(v.json, "late");
}

// A signed value that is no scene (serve passes it over: pass_over) is put back over by the
// node's check with the scene it holds, above the value's revision (every node took that as its
// version), as a refill of the held version; a refill never puts the passed-over value back, and
// the next write follows.
TEST(SceneBus, AValuePassedOverIsPutBackOverAboveItsRevision) {
    Seen seen;
    auto a = bus("passed");
    ASSERT_TRUE(a);
    const BusWrite one = a->write(0, "one");
    ASSERT_EQ(one.error, BusError::kNone) << one.message;
    a->hold({one.revision, 0, one.deadline_ms, "one"});
    SceneBus* node = a.get();
    a->watch(seen.callback([node](const SceneBus::Value& v) {
        if (v.json == "junk")
            node->pass_over(v);  // as serve does with a value that is no scene
        else
            node->hold(v);
    }));
    const auto now_ms = uint64_t(std::chrono::duration_cast<std::chrono::milliseconds>(
                                     std::chrono::system_clock::now().time_since_epoch())
                                     .count());
    ASSERT_TRUE(raw_put("passed", SceneBus::sign(kAdmin, one.revision, now_ms + 5000, "junk")));
    uint64_t junk = 0;
    ASSERT_TRUE(seen.wait(10, [&](const auto& vs) {
        for (const auto& v : vs)
            if (v.json == "junk")
                junk = v.revision;
        return junk != 0 && vs.back().json == "one" && vs.back().refill;
    })) << "the held scene was not put back over the passed-over value";
    const SceneBus::Value back = seen.all().back();
    EXPECT_GT(back.revision, junk);
    EXPECT_EQ(back.of, one.revision);
    EXPECT_EQ(settled(a->counters().refills, 1), 1u);
    auto values = a->signed_values();
    ASSERT_TRUE(values.ok()) << values.error().message;
    ASSERT_FALSE(values->empty());
    EXPECT_EQ(values->front().json, "one");
    for (const auto& v : *values) EXPECT_NE(v.json, "junk");
    // The next write follows the refill.
    const BusWrite two = a->write(back.revision, "two");
    ASSERT_EQ(two.error, BusError::kNone) << two.message;
    ASSERT_TRUE(seen.last_is("two", 10));
}

// A watch blocked inside the NATS client (paused here) does not keep a node behind the bus: the
// 2-s check on its own thread reads the key and delivers the newest write, and puts the held
// scene back on a key deleted meanwhile; the watch, let go, goes on from there.
TEST(SceneBus, TheCheckAloneKeepsANodeUpToTheBus) {
    Seen seen;
    auto a = bus("paused");
    auto writer = bus("paused", "w");
    ASSERT_TRUE(a && writer);
    const BusWrite one = a->write(0, "one");
    ASSERT_EQ(one.error, BusError::kNone) << one.message;
    a->hold({one.revision, 0, one.deadline_ms, "one"});
    SceneBus* node = a.get();
    a->watch(seen.callback([node](const SceneBus::Value& v) { node->hold(v); }));  // as serve
    ASSERT_TRUE(seen.last_is("one", 10)) << "the watch did not deliver the first scene";
    a->pause_watch(true);
    const BusWrite two = writer->write(one.revision, "two");
    ASSERT_EQ(two.error, BusError::kNone) << two.message;
    const BusWrite three = writer->write(two.revision, "three");
    ASSERT_EQ(three.error, BusError::kNone) << three.message;
    ASSERT_TRUE(seen.last_is("three", 15)) << "the check did not bring the node to version "
                                           << three.revision << " while its watch was stopped";
    EXPECT_GE(a->counters().caught_up.load(), 1u);
    // The key deleted while the watch is still stopped: the check puts version three back.
    ASSERT_TRUE(raw_put("paused", "", true));
    uint64_t refilled = 0;
    for (int i = 0; i < 150 && refilled == 0; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
        auto values = writer->signed_values();
        ASSERT_TRUE(values.ok()) << values.error().message;
        if (!values->empty() && values->front().refill)
            refilled = values->front().revision;
    }
    ASSERT_GT(refilled, three.revision) << "the check did not refill the deleted key";
    EXPECT_EQ(settled(a->counters().refills, 1), 1u);
    auto now_values = writer->signed_values();
    ASSERT_TRUE(now_values.ok() && !now_values->empty());
    EXPECT_EQ(now_values->front().json, "three");
    // Let go, the watch delivers what comes next.
    a->pause_watch(false);
    const BusWrite four = writer->write(refilled, "four");
    ASSERT_EQ(four.error, BusError::kNone) << four.message;
    ASSERT_TRUE(seen.last_is("four", 15))
        << "the watch, let go, did not deliver version " << four.revision;
    const auto delivered = seen.all();
    for (size_t i = 1; i < delivered.size(); ++i)
        EXPECT_GE(delivered[i].revision, delivered[i - 1].revision);
}

// A bus found empty or behind the held version gets the newest scene back, at a revision no
// node has applied yet: the held one, unless an admin wrote a later one on the emptied bus.
TEST(SceneBus, RefillPlan) {
    const SceneBus::Value held{7, 6, 1000, "held"};
    // Nothing held (a node still starting), or the bus at or past the held version: no refill.
    EXPECT_FALSE(SceneBus::plan_refill({}, 0, 0, std::nullopt));
    EXPECT_FALSE(SceneBus::plan_refill(held, 7, 7, std::nullopt));
    EXPECT_FALSE(SceneBus::plan_refill(held, 9, 9, std::nullopt));
    // Empty: the held value lands at its own revision (the nodes holding it apply nothing).
    auto empty = SceneBus::plan_refill(held, 0, 0, std::nullopt);
    ASSERT_TRUE(empty);
    EXPECT_EQ(empty->revision, 7u);
    EXPECT_TRUE(empty->ours);
    // A node restarted on the empty bus put its start-up scene (base 0) as version 1: later, but
    // no admin's write, so the held one still goes back.
    auto restarted = SceneBus::plan_refill(held, 1, 1, SceneBus::Value{1, 0, 2000, "start-up"});
    ASSERT_TRUE(restarted);
    EXPECT_TRUE(restarted->ours);
    EXPECT_EQ(restarted->revision, 7u);
    // An admin then wrote version 2 through that node: acknowledged and newer, it goes back, one
    // past the held version so that the nodes holding 7 apply it too.
    auto admin = SceneBus::plan_refill(held, 2, 2, SceneBus::Value{2, 1, 3000, "admin"});
    ASSERT_TRUE(admin);
    EXPECT_FALSE(admin->ours);
    EXPECT_EQ(admin->revision, 8u);
    // A write older than the held one (an old value put again) does not win.
    auto old = SceneBus::plan_refill(held, 2, 2, SceneBus::Value{2, 1, 500, "old"});
    ASSERT_TRUE(old);
    EXPECT_TRUE(old->ours);
    // A lagging node refilled version 6 first (a refill: its deadline is the refill's time, not
    // the write's): it never outranks the held, acknowledged version 7, which goes back at 7.
    SceneBus::Value lagging{6, 5, 9000, "six", true, 6};
    auto over = SceneBus::plan_refill(held, 6, 6, lagging);
    ASSERT_TRUE(over);
    EXPECT_TRUE(over->ours);
    EXPECT_EQ(over->revision, 7u);
    // The key deleted after revision 9 (no value, its sequence at 10): one past the sequence.
    auto deleted = SceneBus::plan_refill(held, 0, 10, std::nullopt);
    ASSERT_TRUE(deleted);
    EXPECT_EQ(deleted->revision, 11u);
}

}  // namespace
}  // namespace hs::cluster
