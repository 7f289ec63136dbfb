// USB headset discovery for hysar-hmd: the table of known headsets (the "usb" matches of the
// profiles in configs/devices/), matching attached devices against it, and listing and watching
// the USB bus with libusb.
//
// usb_devices.cpp (library hs_usb_table) is pure: the table, the matching and the choice of
// --device auto, testable with descriptor fixtures and no USB bus. usb_enumerate.cpp (library
// hs_usb) is the only file that sees libusb (scripts/check_layers.sh holds it). Nothing here
// throws: failures are sentences.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <istream>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace hs::client {

// One attached USB device. `manufacturer` and `product_name` are read only when the device can
// be opened (`strings_read`); otherwise (no permission, or the device refuses) they are empty and
// the device is known by its ids alone.
struct UsbDescriptor {
    uint16_t vendor = 0, product = 0;
    std::string manufacturer, product_name;
    uint8_t bus = 0, address = 0;
    bool strings_read = false;
};

// "04b8:1234": the ids as lsusb prints them.
std::string usb_id(uint16_t vendor, uint16_t product);
// The names of vendors and products from the linux-usb ID list (`usb.ids`, as lsusb reads it).
// Empty when no list is installed: the devices are then known by their ids alone.
struct UsbIdNames {
    std::map<uint16_t, std::string> vendors;
    std::map<uint32_t, std::string> products;  // key: vendor << 16 | product
    std::string file;                          // where it was read; empty when none was
    std::string version;                       // its "# Version:" line, e.g. "2025.07.26"

    // "Seiko Epson Corp." + " " + the product's name; the vendor's alone when the product is not
    // listed; "" when neither is.
    std::string name(uint16_t vendor, uint16_t product) const;
};

// Reads a usb.ids list: vendor lines "vvvv  Name", their product lines "<TAB>pppp  Name"; the
// interface lines and the sections after the vendors (classes "C", "AT", "HID", ...) are
// skipped, and so is a malformed line. Control characters in names become '?'.
UsbIdNames parse_usb_ids(std::istream& in, const std::string& file);

// The system's list: the file named by HYSAR_USB_IDS when it is set, else the first of
// /var/lib/usbutils/usb.ids and /usr/share/misc/usb.ids (Debian's usb.ids package) that exists.
// A missing or unreadable file gives empty names, never an error.
UsbIdNames load_system_usb_ids();

// "bus 001 address 004  04b8:1234  EPSON ..." (or "... (strings not readable)"), followed by
// "  [usb.ids: Seiko Epson Corp. ...]" when `names` knows the ids.
std::string describe_usb(const UsbDescriptor& device, const UsbIdNames* names = nullptr);

// One "usb" entry of a profile: { "vendor_id": "0x04b8", "product_id": "0x1234", "what": "...",
// "source": "..." }.
struct UsbIdMatch {
    uint16_t vendor = 0, product = 0;
    std::string what;    // the headset (or its USB function) as a person names it
    std::string source;  // where the ids come from (a public list, a report, lsusb on site)
    std::string file;    // the file that lists the ids: the profile, or a local entry
};

// A profile of the table: its "name", its file and its USB matches (empty when its ids are not
// known; such a profile is never picked by --device auto). `local` marks a profile that the local
// folder adds (not one of the shipped table).
struct KnownHeadset {
    std::string name, path;
    std::vector<UsbIdMatch> usb;
    bool local = false;
};

// "0x04b8" (or "0X04B8"): 0x and 1 to 4 hexadecimal digits; nullopt for anything else.
std::optional<uint16_t> parse_usb_id(std::string_view text);

// "04b8:0d12" as lsusb prints it (also "0x04b8:0x0d12"): 1 to 4 hexadecimal digits on each side
// of one colon. Returns {vendor, product} or a sentence saying what is wrong.
std::variant<std::pair<uint16_t, uint16_t>, std::string> parse_usb_pair(std::string_view text);

// Every *.json file in `dir` (sorted by name), each a headset profile with a "name" and an
// optional "usb" array. Returns the table, or a sentence naming the file and the entry at fault:
// not JSON, no "name", a "usb" entry without both ids or with a malformed one, a pair of ids
// listed twice (in one profile or in two), a folder without profiles.
std::variant<std::vector<KnownHeadset>, std::string> load_headset_table(const std::string& dir);

// The shipped table (`shipped_dir`, as load_headset_table) with the local folder `local_dir`
// read beside it ("" for none). Each *.json file of the local folder is either a device entry,
// { "profile": "NAME", "usb": [...] }, whose ids are added to the profile NAME of the table (as
// --add-device writes them), or a profile of its own (with "name", as in the shipped table) for a
// headset the shipped table lacks. A pair of ids may appear once in both folders together. An
// error names the file at fault: not JSON, an unknown profile, a profile name the shipped table
// has already, a malformed or repeated id. A local folder without files is fine.
std::variant<std::vector<KnownHeadset>, std::string> load_device_table(
    const std::string& shipped_dir, const std::string& local_dir);

// The file name --add-device gives the entry of `vendor`:`product`: "usb-04b8-0d12.json".
std::string device_entry_file(uint16_t vendor, uint16_t product);

// Writes the local device entry { "profile": profile, "usb": [ { ids, what, source } ] } as
// `dir`/device_entry_file(...) (the folder is made when missing; written to a temporary file and
// renamed, so a reader never sees half a file). Refuses to replace an existing file. Gives the
// path written, or an error naming the path and the reason (no permission, ...). It checks
// nothing else: the caller checks the ids and the profile against the table first, and reads the
// table again after (load_device_table).
struct WrittenEntry {
    std::string path;   // the file written (also set when it failed)
    std::string error;  // empty on success
};
WrittenEntry write_device_entry(const std::string& dir, uint16_t vendor, uint16_t product,
                                const std::string& profile, const std::string& what,
                                const std::string& source);

// The udev rule lines that let the logged-in user (TAG+="uaccess") open every USB device of the
// table: one line per pair of ids, grouped by profile, with a header. The text of
// packaging/70-hysar-headsets.rules for the shipped table (hs_usb_tests compares them).
std::string udev_rules(const std::vector<KnownHeadset>& table);
// One rule line for one pair of ids.
std::string udev_rule_line(uint16_t vendor, uint16_t product);

// An attached device that is a known headset: indices into the descriptors and the table.
struct HeadsetMatch {
    size_t device = 0, headset = 0;
    std::string what;
};

// The attached devices whose vendor and product ids are in the table, in the devices' order.
// Vendor ids alone never match (Epson and Microsoft also make printers and mice).
std::vector<HeadsetMatch> match_headsets(const std::vector<UsbDescriptor>& devices,
                                         const std::vector<KnownHeadset>& table);

// What --device auto picks: `headset` (a table index) when the matches imply exactly one profile
// (two devices of the same headset model imply it once); `conflict` (a sentence naming each
// headset, its bus and address and its profile) when they imply several; neither when none.
struct DeviceChoice {
    std::optional<size_t> headset;
    std::string conflict;
};
DeviceChoice choose_headset(const std::vector<UsbDescriptor>& devices,
                            const std::vector<KnownHeadset>& table,
                            const std::vector<HeadsetMatch>& matches);

// ---- libusb (usb_enumerate.cpp, library hs_usb) ----

// The devices on every USB bus this process can see, or a sentence saying why there is no list:
// no USB bus on this machine (a container), no permission to the bus, libusb could not start.
// An empty list means a bus without devices. Never throws.
std::variant<std::vector<UsbDescriptor>, std::string> list_usb_devices();

// An arrival or departure seen by watch_usb_devices. `present` marks the devices already attached
// when the watch started (reported once, as arrivals).
struct UsbEvent {
    bool arrived = true, present = false;
    UsbDescriptor device;
};

// Reports arrivals and departures to `on_event` (on this thread) for `seconds`, or until `stop`
// returns true when `seconds` is 0; `stop` is asked at least every 250 ms. Returns nullopt after
// the watch, or a sentence when it cannot watch: libusb cannot start, or this libusb on this
// system has no hot-plug support (LIBUSB_CAP_HAS_HOTPLUG). Never throws.
std::optional<std::string> watch_usb_devices(double seconds, const std::function<bool()>& stop,
                                             const std::function<void(const UsbEvent&)>& on_event);

}  // namespace hs::client
