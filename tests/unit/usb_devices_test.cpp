// USB headset discovery without a USB bus: the table of known headsets (configs/devices/ and the
// fixture table tests/data/usb_table/) and the matching of descriptor lists against it.
#include <filesystem>
#include <fstream>
#include <set>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "clients/common.hpp"
#include "clients/usb_devices.hpp"

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

}  // namespace
