// USB headset discovery without a USB bus: the table of known headsets (configs/devices/ and the
// fixture table tests/data/usb_table/), the local device entries beside it, the names from
// usb.ids (tests/data/usb_ids/), the udev rule of the shipped ids, and the matching of
// descriptor lists against them.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "clients/common/common.hpp"
#include "clients/usb_table/usb_devices.hpp"

using namespace hs::client;

namespace {

const std::string kFixtureTable = HYSAR_SOURCE_DIR "/tests/data/usb_table";

UsbDescriptor dev(uint16_t vendor, uint16_t product, uint8_t bus, uint8_t address,
                  std::string manufacturer = "", std::string product_name = "") {
    UsbDescriptor d;
    d.vendor = vendor;
    d.product = product;
    d.bus = bus;
    d.address = address;
    d.strings_read = !manufacturer.empty() || !product_name.empty();
    d.manufacturer = std::move(manufacturer);
    d.product_name = std::move(product_name);
    return d;
}

// Descriptor fixtures. Unrelated devices carry their real ids (USB ID repository); the headsets
// carry the fixture table's made-up product ids.
const UsbDescriptor kRootHub2 = dev(0x1d6b, 0x0002, 1, 1, "Linux Foundation", "2.0 root hub");
const UsbDescriptor kRootHub3 = dev(0x1d6b, 0x0003, 2, 1, "Linux Foundation", "3.0 root hub");
const UsbDescriptor kMouse = dev(0x046d, 0xc077, 1, 3);  // Logitech M105, strings not readable
const UsbDescriptor kBluetooth = dev(0x8087, 0x0a2b, 1, 5, "Intel Corp.", "Bluetooth");
const UsbDescriptor kEpsonPrinter = dev(0x04b8, 0x0e03, 1, 6, "EPSON", "TM-T20");
const UsbDescriptor kMicrosoftMouse = dev(0x045e, 0x0823, 1, 7, "Microsoft", "IntelliMouse");
const UsbDescriptor kMoverio = dev(0x04b8, 0xfe30, 1, 4, "EPSON", "EMBT3C");
const UsbDescriptor kMoverioMode2 = dev(0x04b8, 0xfe31, 1, 8);
const UsbDescriptor kHoloLens2 = dev(0x045e, 0xfe02, 2, 3, "Microsoft", "HoloLens 2");

std::vector<KnownHeadset> fixture_table() {
    auto t = load_headset_table(kFixtureTable);
    if (auto* e = std::get_if<std::string>(&t))
        ADD_FAILURE() << *e;
    return t.index() == 0 ? std::get<0>(t) : std::vector<KnownHeadset>{};
}

size_t index_of(const std::vector<KnownHeadset>& table, const std::string& name) {
    for (size_t i = 0; i < table.size(); ++i)
        if (table[i].name == name)
            return i;
    ADD_FAILURE() << "no profile " << name;
    return table.size();
}

TEST(UsbIds, ParsesLsusbStyleHex) {
    EXPECT_EQ(parse_usb_id("0x04b8"), 0x04b8);
    EXPECT_EQ(parse_usb_id("0X04B8"), 0x04b8);
    EXPECT_EQ(parse_usb_id("0x1"), 0x0001);
    EXPECT_EQ(parse_usb_id("0xffff"), 0xffff);
    for (const char* bad : {"", "04b8", "0x", "0x12345", "0xg0", " 0x04b8", "0x04b8 ", "x04b8"})
        EXPECT_FALSE(parse_usb_id(bad)) << "'" << bad << "'";
    EXPECT_EQ(usb_id(0x04b8, 0x0e03), "04b8:0e03");
}

TEST(UsbIds, DescribesADeviceWithOrWithoutItsStrings) {
    EXPECT_EQ(describe_usb(kMoverio), "bus 001 address 004  04b8:fe30  EPSON EMBT3C");
    EXPECT_EQ(describe_usb(kMouse), "bus 001 address 003  046d:c077  (strings not readable)");
}

TEST(UsbTable, FixtureTableLoads) {
    const auto table = fixture_table();
    ASSERT_EQ(table.size(), 3u);  // sorted by file name
    EXPECT_EQ(table[0].name, "hololens2");
    EXPECT_EQ(table[1].name, "magicleap1");
    EXPECT_TRUE(table[1].usb.empty());
    ASSERT_EQ(table[2].usb.size(), 2u);
    EXPECT_EQ(table[2].usb[1].vendor, 0x04b8);
    EXPECT_EQ(table[2].usb[1].product, 0xfe31);
    EXPECT_EQ(table[2].path, kFixtureTable + "/moverio-bt300.json");
}

TEST(UsbMatch, NoDevices) {
    const auto table = fixture_table();
    const std::vector<UsbDescriptor> none;
    const auto m = match_headsets(none, table);
    EXPECT_TRUE(m.empty());
    const auto c = choose_headset(none, table, m);
    EXPECT_FALSE(c.headset);
    EXPECT_TRUE(c.conflict.empty());
}

TEST(UsbMatch, VendorIdAloneNeverMatches) {
    const auto table = fixture_table();
    const std::vector<UsbDescriptor> devices{kRootHub2, kMouse, kEpsonPrinter, kMicrosoftMouse};
    const auto m = match_headsets(devices, table);
    EXPECT_TRUE(m.empty());
    EXPECT_FALSE(choose_headset(devices, table, m).headset);
}

TEST(UsbMatch, OneMoverio) {
    const auto table = fixture_table();
    const std::vector<UsbDescriptor> devices{kRootHub2, kMoverio};
    const auto m = match_headsets(devices, table);
    ASSERT_EQ(m.size(), 1u);
    EXPECT_EQ(m[0].device, 1u);
    EXPECT_EQ(m[0].headset, index_of(table, "moverio-bt300"));
    EXPECT_EQ(m[0].what, "Epson MOVERIO BT-300 (test id)");
    const auto c = choose_headset(devices, table, m);
    ASSERT_TRUE(c.headset);
    EXPECT_EQ(table[*c.headset].path, kFixtureTable + "/moverio-bt300.json");
    EXPECT_TRUE(c.conflict.empty());
}

TEST(UsbMatch, OneHoloLens2AmongUnrelatedDevices) {
    const auto table = fixture_table();
    const std::vector<UsbDescriptor> devices{kRootHub2,  kRootHub3,     kMouse,
                                             kBluetooth, kEpsonPrinter, kHoloLens2};
    const auto m = match_headsets(devices, table);
    ASSERT_EQ(m.size(), 1u);
    EXPECT_EQ(m[0].device, 5u);
    const auto c = choose_headset(devices, table, m);
    ASSERT_TRUE(c.headset);
    EXPECT_EQ(table[*c.headset].name, "hololens2");
}

TEST(UsbMatch, TwoDifferentHeadsetsAreAConflictNamingBoth) {
    const auto table = fixture_table();
    const std::vector<UsbDescriptor> devices{kHoloLens2, kMouse, kMoverio};
    const auto m = match_headsets(devices, table);
    ASSERT_EQ(m.size(), 2u);
    const auto c = choose_headset(devices, table, m);
    EXPECT_FALSE(c.headset);
    for (const std::string part :
         {"2 different known headsets", "Microsoft HoloLens 2 (test id)", "045e:fe02",
          "bus 2 address 3", "/hololens2.json", "Epson MOVERIO BT-300 (test id)", "04b8:fe30",
          "bus 1 address 4", "/moverio-bt300.json", " and "})
        EXPECT_NE(c.conflict.find(part), std::string::npos) << part << " not in: " << c.conflict;
}

TEST(UsbMatch, OneHeadsetSeenAsTwoDevicesImpliesItsProfileOnce) {
    const auto table = fixture_table();
    const std::vector<UsbDescriptor> devices{kMoverio, kRootHub2, kMoverioMode2};
    const auto m = match_headsets(devices, table);
    ASSERT_EQ(m.size(), 2u);
    const auto c = choose_headset(devices, table, m);
    ASSERT_TRUE(c.headset);
    EXPECT_EQ(table[*c.headset].name, "moverio-bt300");
    EXPECT_TRUE(c.conflict.empty());
}

// A scratch folder of profiles, removed at the end.
class UsbTableDir : public ::testing::Test {
protected:
    void SetUp() override {
        dir_ =
            std::filesystem::temp_directory_path() /
            ("hs_usb_table_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
             "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
        std::filesystem::remove_all(dir_);
        std::filesystem::create_directories(dir_);
    }
    void TearDown() override { std::filesystem::remove_all(dir_); }
    void write(const std::string& file, const std::string& text) {
        std::ofstream(dir_ / file) << text;
    }
    std::string error() {
        auto t = load_headset_table(dir_.string());
        if (auto* e = std::get_if<std::string>(&t))
            return *e;
        ADD_FAILURE() << "the table loaded";
        return "";
    }
    std::filesystem::path dir_;
};

TEST_F(UsbTableDir, RefusesMalformedIdsNamingFileAndEntry) {
    write("a.json",
          R"({ "name": "a", "usb": [ { "vendor_id": "0x04b8", "product_id": "1234" } ]})");
    const std::string e = error();
    EXPECT_NE(e.find("a.json"), std::string::npos) << e;
    EXPECT_NE(e.find("usb[0].product_id = \"1234\""), std::string::npos) << e;
}

TEST_F(UsbTableDir, RefusesNumbersMissingIdsAndNonArrays) {
    write("a.json", R"({ "name": "a", "usb": [ { "vendor_id": 1208, "product_id": "0x1234" } ]})");
    EXPECT_NE(error().find("usb[0].vendor_id = 1208"), std::string::npos);
    write("a.json", R"({ "name": "a", "usb": [ { "vendor_id": "0x04b8" } ]})");
    EXPECT_NE(error().find("usb[0]: 'product_id' is missing"), std::string::npos);
    write("a.json", R"({ "name": "a", "usb": { "vendor_id": "0x04b8" } })");
    EXPECT_NE(error().find("'usb' must be an array"), std::string::npos);
}

TEST_F(UsbTableDir, RefusesOneIdPairInTwoProfiles) {
    const std::string entry = R"([ { "vendor_id": "0x04b8", "product_id": "0x1234" } ])";
    write("a.json", R"({ "name": "a", "usb": )" + entry + "}");
    write("b.json", R"({ "name": "b", "usb": )" + entry + "}");
    const std::string e = error();
    EXPECT_NE(e.find("b.json': 04b8:1234 is already the USB id of"), std::string::npos) << e;
    EXPECT_NE(e.find("a.json"), std::string::npos) << e;
}

TEST_F(UsbTableDir, RefusesNoNameBadJsonAndAnEmptyFolder) {
    EXPECT_NE(error().find("no headset profile"), std::string::npos);
    write("a.json", R"({ "usb": [] })");
    EXPECT_NE(error().find("'name' (a non-empty string) is missing"), std::string::npos);
    write("a.json", "{ \"name\": ");
    EXPECT_NE(error().find("not valid JSON"), std::string::npos);
    auto t = load_headset_table((dir_ / "nowhere").string());
    ASSERT_EQ(t.index(), 1u);
    EXPECT_NE(std::get<1>(t).find("is not a folder"), std::string::npos);
}

TEST_F(UsbTableDir, AProfileWithoutUsbIdsLoadsAndNeverMatches) {
    write("a.json", R"({ "name": "a" })");
    auto t = load_headset_table(dir_.string());
    ASSERT_EQ(t.index(), 0u);
    const auto& table = std::get<0>(t);
    ASSERT_EQ(table.size(), 1u);
    EXPECT_TRUE(table[0].usb.empty());
    EXPECT_TRUE(match_headsets({kMoverio, kHoloLens2}, table).empty());
}

// The shipped table: every profile is a valid display, named as its file, declares its "usb"
// array, and one whose ids are unknown says so in its comment.
TEST(UsbTable, ShippedProfilesAreValid) {
    const std::string dir = HYSAR_SOURCE_DIR "/configs/devices";
    auto t = load_headset_table(dir);
    ASSERT_EQ(t.index(), 0u) << std::get<1>(t);
    const auto& table = std::get<0>(t);
    std::set<std::string> names;
    for (const auto& h : table) names.insert(h.name);
    for (const char* want :
         {"hololens", "hololens2", "magicleap1", "moverio-bt200", "moverio-bt300"})
        EXPECT_TRUE(names.count(want)) << want;
    for (const auto& h : table) {
        SCOPED_TRACE(h.path);
        EXPECT_EQ(std::filesystem::path(h.path).stem().string(), h.name);
        hs::protocol::RegisterDisplay d;
        const auto err = load_profile(h.path, 1.0, &d);
        EXPECT_FALSE(err) << *err;
        std::ifstream in(h.path);
        const auto j = nlohmann::json::parse(in);
        ASSERT_TRUE(j.contains("usb"));
        if (h.usb.empty()) {
            EXPECT_NE(j.value("comment", "").find("could not be confirmed"), std::string::npos);
        }
    }
}

// The clients' default files: the installed tree beside the binary, then the source tree; a file
// in neither is an error that names every path tried.
TEST(ConfigFiles, DefaultsComeFromTheInstalledThenTheSourceTree) {
    const auto dirs = config_dirs();
    ASSERT_EQ(dirs.size(), 2u);
    EXPECT_EQ(std::filesystem::path(dirs[0]).filename(), "configs");
    EXPECT_EQ(std::filesystem::path(dirs[0]).parent_path().filename(), "hysar");
    EXPECT_EQ(std::filesystem::path(dirs[1]), std::filesystem::path(HYSAR_SOURCE_DIR "/configs"));
    const ConfigFile found = find_config("devices/hololens.json");
    EXPECT_EQ(found.path, HYSAR_SOURCE_DIR "/configs/devices/hololens.json");
    EXPECT_EQ(found.error, "");
    const ConfigFile missing = find_config("devices/no-such-headset.json");
    EXPECT_EQ(missing.path, "");
    for (const auto& d : dirs)
        EXPECT_NE(missing.error.find(d + "/devices/no-such-headset.json"), std::string::npos)
            << missing.error;
}

// ---- The shipped table's public ids (configs/devices/) ----

const std::string kShippedTable = HYSAR_SOURCE_DIR "/configs/devices";

std::vector<KnownHeadset> shipped_table() {
    auto t = load_headset_table(kShippedTable);
    if (auto* e = std::get_if<std::string>(&t))
        ADD_FAILURE() << *e;
    return t.index() == 0 ? std::get<0>(t) : std::vector<KnownHeadset>{};
}

// The profile --device auto picks for `devices` with `table`, "" for none, "conflict: ..."
std::string auto_pick(const std::vector<UsbDescriptor>& devices,
                      const std::vector<KnownHeadset>& table) {
    const auto c = choose_headset(devices, table, match_headsets(devices, table));
    if (!c.conflict.empty())
        return "conflict: " + c.conflict;
    return c.headset ? table[*c.headset].name : "";
}

// Every public id, on a bus with a root hub and a mouse: the headset's profile, alone.
TEST(UsbShipped, EachPublicIdPicksItsProfile) {
    const auto table = shipped_table();
    const struct {
        uint16_t vendor, product;
        const char* profile;
    } ids[] = {{0x2c55, 0xa100, "magicleap1"},   {0x2c55, 0xb100, "magicleap1"},
               {0x2c55, 0xc001, "magicleap1"},   {0x2c55, 0xc002, "magicleap1"},
               {0x04b8, 0x0d12, "moverio-bt40"}, {0x04b8, 0x0335, "moverio-bt40"}};
    for (const auto& id : ids) {
        SCOPED_TRACE(usb_id(id.vendor, id.product));
        const std::vector<UsbDescriptor> devices{kRootHub2, kMouse,
                                                 dev(id.vendor, id.product, 1, 9)};
        const auto m = match_headsets(devices, table);
        ASSERT_EQ(m.size(), 1u);
        EXPECT_EQ(m[0].device, 2u);
        EXPECT_EQ(auto_pick(devices, table), id.profile);
        EXPECT_EQ(table[m[0].headset].path, kShippedTable + "/" + id.profile + ".json");
    }
    // The table lists exactly these ids: no profile claims one that no public source gave.
    size_t listed = 0;
    for (const auto& h : table) listed += h.usb.size();
    EXPECT_EQ(listed, std::size(ids));
}

// The Lightpack in either mode and the Control are one headset: any of them together picks the
// Magic Leap One profile once, never a conflict; so do the BT-40's two functions.
TEST(UsbShipped, AHeadsetsSeveralDevicesAreOneHeadset) {
    const auto table = shipped_table();
    const std::vector<UsbDescriptor> magic_leap{
        dev(0x2c55, 0xa100, 1, 4), kMouse, dev(0x2c55, 0xc001, 1, 5), dev(0x2c55, 0xc002, 1, 6)};
    EXPECT_EQ(match_headsets(magic_leap, table).size(), 3u);
    EXPECT_EQ(auto_pick(magic_leap, table), "magicleap1");
    EXPECT_EQ(auto_pick({dev(0x2c55, 0xb100, 2, 2), dev(0x2c55, 0xc002, 2, 3)}, table),
              "magicleap1");
    EXPECT_EQ(auto_pick({dev(0x04b8, 0x0335, 3, 7), dev(0x04b8, 0x0d12, 3, 8)}, table),
              "moverio-bt40");
}

// 045e:0659 "HoloLens Sensors" is the sensor hub of tethered Windows Mixed Reality VR headsets
// (HP Reverb and others), not a HoloLens: it matches no profile, and beside a known headset it
// changes nothing.
TEST(UsbShipped, TheWmrSensorHubMatchesNothing) {
    const auto table = shipped_table();
    const UsbDescriptor wmr = dev(0x045e, 0x0659, 2, 4, "Microsoft", "HoloLens Sensors");
    EXPECT_TRUE(match_headsets({wmr}, table).empty());
    EXPECT_EQ(auto_pick({kRootHub3, wmr, kMicrosoftMouse}, table), "");
    EXPECT_EQ(auto_pick({wmr, dev(0x04b8, 0x0d12, 1, 4)}, table), "moverio-bt40");
}

TEST(UsbShipped, TwoKnownHeadsetsAreAConflictNamingBoth) {
    const auto table = shipped_table();
    const std::vector<UsbDescriptor> devices{dev(0x2c55, 0xa100, 1, 4), kMouse,
                                             dev(0x04b8, 0x0d12, 2, 7)};
    const std::string pick = auto_pick(devices, table);
    for (const std::string& part : std::vector<std::string>{
             "conflict: 2 different known headsets are attached: ", "Magic Leap One Lightpack",
             "2c55:a100, bus 1 address 4, profile " + kShippedTable + "/magicleap1.json",
             " and Epson MOVERIO BT-40",
             "04b8:0d12, bus 2 address 7, profile " + kShippedTable + "/moverio-bt40.json"})
        EXPECT_NE(pick.find(part), std::string::npos) << part << " not in: " << pick;
}

// Each shipped id says where it comes from; the ones from usb.ids cite the Debian package.
TEST(UsbShipped, EveryIdNamesItsSource) {
    for (const auto& h : shipped_table())
        for (const auto& m : h.usb) {
            SCOPED_TRACE(h.name + " " + usb_id(m.vendor, m.product));
            EXPECT_FALSE(m.what.empty());
            EXPECT_NE(m.source.find("usb.ids 2025.07.26 (Debian package usb.ids "
                                    "2025.07.26-0+deb12u1)"),
                      std::string::npos)
                << m.source;
        }
}

// The BT-40: 1920 x 1080 per eye, 34 deg diagonal; horizontal and vertical from 16:9.
TEST(UsbShipped, MoverioBt40ProfileIsItsPublishedDisplay) {
    hs::protocol::RegisterDisplay d;
    const auto err = load_profile(kShippedTable + "/moverio-bt40.json", 1.0, &d);
    ASSERT_FALSE(err) << *err;
    EXPECT_EQ(d.eye_width, 1920u);
    EXPECT_EQ(d.eye_height, 1080u);
    const double deg = M_PI / 180.0;
    const double fov_x = 2 * std::atan(0.5 * d.eye_width / d.fx) / deg;
    const double fov_y = 2 * std::atan(0.5 * d.eye_height / d.fy) / deg;
    const double fov_d =
        2 * std::atan(std::hypot(0.5 * d.eye_width / d.fx, 0.5 * d.eye_height / d.fy)) / deg;
    EXPECT_NEAR(fov_d, 34.0, 1e-9);
    EXPECT_NEAR(fov_x, 29.84, 0.01);  // tan(h/2) = tan(17 deg) * 16 / sqrt(16^2 + 9^2)
    EXPECT_NEAR(fov_y, 17.05, 0.01);
    EXPECT_NEAR(d.fx, d.fy, 1e-9);  // square pixels
}

// ---- packaging/70-hysar-headsets.rules: exactly the shipped table's ids ----

TEST(UsbUdevRule, ListsExactlyTheShippedIds) {
    const auto table = shipped_table();
    const std::string path = HYSAR_SOURCE_DIR "/packaging/70-hysar-headsets.rules";
    std::ifstream in(path);
    ASSERT_TRUE(in) << path;
    std::stringstream text;
    text << in.rdbuf();
    std::set<std::string> in_rule, in_table;
    std::istringstream lines(text.str());
    for (std::string line; std::getline(lines, line);) {
        const auto v = line.find("ATTR{idVendor}==\""), p = line.find("ATTR{idProduct}==\"");
        if (line.empty() || line[0] == '#')
            continue;
        ASSERT_NE(v, std::string::npos) << line;
        ASSERT_NE(p, std::string::npos) << line;
        EXPECT_NE(line.find("TAG+=\"uaccess\""), std::string::npos) << line;
        in_rule.insert(line.substr(v + 17, 4) + ":" + line.substr(p + 18, 4));
    }
    for (const auto& h : table)
        for (const auto& m : h.usb) in_table.insert(usb_id(m.vendor, m.product));
    EXPECT_EQ(in_rule, in_table);
    EXPECT_EQ(in_rule.count("045e:0659"), 0u);
    // The whole file is what udev_rules() makes of the table, comments included.
    EXPECT_EQ(text.str(), udev_rules(table)) << "put this text in " << path << ":\n"
                                             << udev_rules(table);
}

// ---- Names from usb.ids (tests/data/usb_ids/usb.ids, an excerpt of the Debian package's) ----

UsbIdNames fixture_names() {
    const std::string path = HYSAR_SOURCE_DIR "/tests/data/usb_ids/usb.ids";
    std::ifstream in(path);
    EXPECT_TRUE(in) << path;
    return parse_usb_ids(in, path);
}

TEST(UsbIdNames, ReadsVendorsAndProductsAndSkipsTheClasses) {
    const auto names = fixture_names();
    EXPECT_EQ(names.version, "2025.07.26");
    EXPECT_EQ(names.vendors.size(), 5u);
    EXPECT_EQ(names.name(0x2c55, 0xa100), "Magic Leap, Inc. ML1 Lightpack (MLDB)");
    EXPECT_EQ(names.name(0x2c55, 0xc002), "Magic Leap, Inc. ML1 Control (Bootloader)");
    EXPECT_EQ(names.name(0x046d, 0xc077), "Logitech, Inc. Mouse");
    // A product the list lacks: the vendor alone (the BT-40's ids are not in 2025.07.26).
    EXPECT_EQ(names.name(0x04b8, 0x0d12), "Seiko Epson Corp.");
    EXPECT_EQ(names.name(0x045e, 0x0659), "Microsoft Corp.");
    EXPECT_EQ(names.name(0x1234, 0x5678), "");
    // The class section's "<TAB>01  Control Device" is no product of the last vendor.
    size_t magic_leap = 0;
    for (const auto& [key, name] : names.products) magic_leap += (key >> 16) == 0x2c55;
    EXPECT_EQ(magic_leap, 4u);
    EXPECT_EQ(names.products.count(0x2c550001u), 0u);
}

TEST(UsbIdNames, DescribeAddsTheListedName) {
    const auto names = fixture_names();
    EXPECT_EQ(describe_usb(kMouse, &names),
              "bus 001 address 003  046d:c077  (strings not readable)  [usb.ids: Logitech, "
              "Inc. Mouse]");
    EXPECT_EQ(describe_usb(kMoverio, &names),
              "bus 001 address 004  04b8:fe30  EPSON EMBT3C  [usb.ids: Seiko Epson Corp.]");
    EXPECT_EQ(describe_usb(dev(0x1234, 0x5678, 1, 2), &names),
              "bus 001 address 002  1234:5678  (strings not readable)");
    const UsbIdNames none;
    EXPECT_EQ(describe_usb(kMouse, &none), describe_usb(kMouse));
}

TEST(UsbIdNames, ToleratesCrlfControlCharactersAndAnEmptyList) {
    std::istringstream in(
        "# Version: 1\r\n0001  A\x01"
        "B  \r\n\t0002  C\r\nnot an id\n");
    const auto names = parse_usb_ids(in, "x");
    EXPECT_EQ(names.version, "1");
    EXPECT_EQ(names.name(0x0001, 0x0002), "A?B C");
    std::istringstream empty("");
    EXPECT_TRUE(parse_usb_ids(empty, "y").vendors.empty());
}

TEST(UsbIds, ParsesVendorProductPairs) {
    using Pair = std::pair<uint16_t, uint16_t>;
    for (const char* good : {"04b8:0d12", "0x04b8:0x0D12", "4b8:d12"}) {
        auto p = parse_usb_pair(good);
        ASSERT_EQ(p.index(), 0u) << good;
        EXPECT_EQ(std::get<0>(p), Pair(0x04b8, 0x0d12)) << good;
    }
    for (const char* bad : {"", "04b8", "04b8:", ":0d12", "04b8-0d12", "04b8:0d12:1", "04b8:10d12",
                            "g4b8:0d12", " 04b8:0d12", "04b8:0d12 "}) {
        auto p = parse_usb_pair(bad);
        ASSERT_EQ(p.index(), 1u) << bad;
        EXPECT_NE(std::get<1>(p).find("expected VENDOR:PRODUCT"), std::string::npos);
    }
}

// ---- The local folder beside the shipped table (--devices-dir, --add-device) ----

TEST_F(UsbTableDir, AnAddedEntryRoundTrips) {
    const std::string local = dir_.string();
    const auto written = write_device_entry(local, 0x04b8, 0xfe30, "moverio-bt300",
                                            "Epson MOVERIO BT-300 (on site)", "lsusb on site");
    ASSERT_EQ(written.error, "");
    EXPECT_EQ(written.path, local + "/usb-04b8-fe30.json");
    auto t = load_device_table(kShippedTable, local);
    ASSERT_EQ(t.index(), 0u) << std::get<1>(t);
    const auto& table = std::get<0>(t);
    EXPECT_EQ(auto_pick({kRootHub2, kMoverio}, table), "moverio-bt300");
    const auto m = match_headsets({kMoverio}, table);
    ASSERT_EQ(m.size(), 1u);
    EXPECT_EQ(m[0].what, "Epson MOVERIO BT-300 (on site)");
    EXPECT_EQ(table[m[0].headset].path, kShippedTable + "/moverio-bt300.json");
    EXPECT_EQ(table[m[0].headset].usb.back().file, written.path);
    EXPECT_EQ(table[m[0].headset].usb.back().source, "lsusb on site");
    // The shipped ids still match beside it.
    EXPECT_EQ(auto_pick({dev(0x2c55, 0xa100, 1, 4)}, table), "magicleap1");
    // The file is a plain entry a person can read and remove; it is never replaced.
    std::ifstream in(written.path);
    const auto j = nlohmann::json::parse(in);
    EXPECT_EQ(j["profile"], "moverio-bt300");
    EXPECT_EQ(j["usb"][0]["vendor_id"], "0x04b8");
    EXPECT_EQ(j["usb"][0]["product_id"], "0xfe30");
    const auto again = write_device_entry(local, 0x04b8, 0xfe30, "hololens", "", "");
    EXPECT_NE(again.error.find("exists already"), std::string::npos) << again.error;
    EXPECT_FALSE(std::filesystem::exists(written.path + ".tmp"));
}

TEST_F(UsbTableDir, WritingMakesTheFolder) {
    const std::string local = (dir_ / "etc" / "hysar" / "devices").string();
    const auto written = write_device_entry(local, 0x1234, 0x0001, "hololens2", "x", "y");
    ASSERT_EQ(written.error, "");
    auto t = load_device_table(kShippedTable, local);
    ASSERT_EQ(t.index(), 0u) << std::get<1>(t);
    EXPECT_EQ(auto_pick({dev(0x1234, 0x0001, 1, 2)}, std::get<0>(t)), "hololens2");
}

TEST_F(UsbTableDir, ALocalProfileOfItsOwnIsFound) {
    write("my-headset.json", R"({ "name": "my-headset", "eye_width": 640, "eye_height": 480,
        "fov_x_deg": 40, "fov_y_deg": 30, "usb": [ { "vendor_id": "0x1234", "product_id": "0x0042" } ] })");
    auto t = load_device_table(kShippedTable, dir_.string());
    ASSERT_EQ(t.index(), 0u) << std::get<1>(t);
    const auto& table = std::get<0>(t);
    EXPECT_EQ(auto_pick({dev(0x1234, 0x0042, 1, 2)}, table), "my-headset");
    EXPECT_TRUE(table.back().local);
    EXPECT_FALSE(table.front().local);
}

TEST_F(UsbTableDir, ABrokenLocalFileIsAnErrorNamingIt) {
    const std::string local = dir_.string();
    auto error_of = [&]() {
        auto t = load_device_table(kShippedTable, local);
        return t.index() == 1 ? std::get<1>(t) : std::string("the table loaded");
    };
    write("usb-1234-0001.json", "{ \"profile\": ");
    EXPECT_NE(error_of().find(local + "/usb-1234-0001.json': not valid JSON"), std::string::npos)
        << error_of();
    write(
        "usb-1234-0001.json",
        R"({ "profile": "no-such", "usb": [ { "vendor_id": "0x1234", "product_id": "0x0001" } ] })");
    EXPECT_NE(error_of().find("usb-1234-0001.json': 'profile' = \"no-such\" is not a profile of "
                              "the table (it has hololens, hololens2, magicleap1"),
              std::string::npos)
        << error_of();
    write("usb-1234-0001.json", R"({ "profile": "hololens", "usb": [] })");
    EXPECT_NE(error_of().find("needs at least one pair of ids"), std::string::npos);
    write(
        "usb-1234-0001.json",
        R"({ "profile": "hololens", "usb": [ { "vendor_id": "0x2c55", "product_id": "0xa100" } ] })");
    EXPECT_NE(error_of().find("usb-1234-0001.json': 2c55:a100 is already the USB id of '" +
                              kShippedTable + "/magicleap1.json' (profile magicleap1)"),
              std::string::npos)
        << error_of();
    write("usb-1234-0001.json", R"({ "name": "hololens", "usb": [] })");
    EXPECT_NE(error_of().find("the profile 'hololens' is in the table already"), std::string::npos)
        << error_of();
    write("usb-1234-0001.json", R"({ "vendor_id": "0x1234" })");
    EXPECT_NE(error_of().find("expected a device entry"), std::string::npos) << error_of();
    std::filesystem::remove(dir_ / "usb-1234-0001.json");
    EXPECT_EQ(error_of(), "the table loaded");  // an empty local folder is fine
    auto t = load_device_table(kShippedTable, (dir_ / "nowhere").string());
    ASSERT_EQ(t.index(), 1u);
    EXPECT_NE(std::get<1>(t).find("is not a folder of local device entries"), std::string::npos);
}

}  // namespace
