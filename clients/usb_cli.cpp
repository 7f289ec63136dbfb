#include "clients/usb_cli.hpp"

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <ctime>
#include <filesystem>

#include "clients/common/common.hpp"
#include "clients/usb_table/usb_devices.hpp"

namespace hs::client {

namespace {

volatile std::sig_atomic_t g_stop = 0;
extern "C" void on_stop_signal(int) {
    g_stop = 1;
}

// The local folder to read beside the shipped table: --devices-dir (which must exist), else the
// default one when it exists, else none ("").
std::string local_dir_to_read(const Args& args) {
    if (args.has("--devices-dir")) {
        const std::string dir = args.get("--devices-dir", "");
        std::error_code ec;
        if (dir.empty() || !std::filesystem::is_directory(dir, ec))
            args.fail("--devices-dir '" + dir +
                      "' is not a folder (hysar-hmd --add-device makes it; leave the option out "
                      "to read " +
                      kLocalDevicesDir + " when it exists)");
        return dir;
    }
    std::error_code ec;
    return std::filesystem::is_directory(kLocalDevicesDir, ec) ? kLocalDevicesDir : "";
}

// The shipped table's folder: --device-table, or the configs' devices/ folder.
std::string shipped_dir(const Args& args) {
    if (args.has("--device-table"))
        return args.get("--device-table", "");
    const ConfigFile found = find_config("devices");
    if (found.path.empty())
        args.fail("the known-headset table: " + found.error + "; give --device-table DIR");
    return found.path;
}

// The shipped table with the local folder `local_dir` ("": none).
std::vector<KnownHeadset> read_table(const Args& args, const std::string& local_dir) {
    auto table = load_device_table(shipped_dir(args), local_dir);
    if (auto* e = std::get_if<std::string>(&table)) {
        // Say which folder the file at fault belongs to.
        const bool local = !local_dir.empty() && e->rfind("'" + local_dir, 0) == 0;
        args.fail((local ? "local device entries: " : "--device-table ") + *e);
    }
    return std::get<std::vector<KnownHeadset>>(std::move(table));
}
std::vector<KnownHeadset> read_table(const Args& args) {
    return read_table(args, local_dir_to_read(args));
}

size_t profiles_with_ids(const std::vector<KnownHeadset>& table) {
    size_t n = 0;
    for (const auto& h : table) n += !h.usb.empty();
    return n;
}

std::string headset_name(const KnownHeadset& h, const std::string& what) {
    return what.empty() ? h.name : what;
}

int list_devices(const Args& args, const std::vector<KnownHeadset>& table,
                 const std::string& configured) {
    const std::string keep = "the configured profile will be used: " + configured +
                             (args.has("--profile") ? " (--profile)" : " (the default --profile)");
    auto listed = list_usb_devices();
    if (auto* e = std::get_if<std::string>(&listed)) {
        std::printf("No USB devices listed: %s.\nNo headset detected: %s\n", e->c_str(),
                    keep.c_str());
        return 0;
    }
    const auto& devices = std::get<std::vector<UsbDescriptor>>(listed);
    const auto matches = match_headsets(devices, table);
    if (devices.empty()) {
        std::error_code ec;
        std::printf("USB devices: none%s\n",
                    std::filesystem::exists("/dev/bus/usb", ec)
                        ? ""
                        : " (no /dev/bus/usb: this machine or container shows no USB bus)");
    } else {
        std::printf("USB devices: %zu\n", devices.size());
    }
    const UsbIdNames ids = load_system_usb_ids();
    size_t unreadable = 0;
    for (size_t d = 0; d < devices.size(); ++d) {
        std::string line = "  " + describe_usb(devices[d], &ids);
        for (const auto& m : matches)
            if (m.device == d)
                line += "  <- known headset: " + headset_name(table[m.headset], m.what) +
                        ", profile " + table[m.headset].path;
        std::printf("%s\n", line.c_str());
        unreadable += !devices[d].strings_read;
    }
    if (unreadable)
        std::printf(
            "(%zu of %zu devices could not be opened to read their names, most likely no "
            "permission to the USB bus: they are known by their ids)\n",
            unreadable, devices.size());
    if (!devices.empty()) {
        if (ids.file.empty())
            std::printf(
                "(no usb.ids list on this machine: install the usb.ids package to see the "
                "devices' names in [ ])\n");
        else
            std::printf("(names in [ ] from %s%s)\n", ids.file.c_str(),
                        ids.version.empty() ? "" : (", version " + ids.version).c_str());
    }
    const DeviceChoice choice = choose_headset(devices, table, matches);
    if (choice.headset) {
        std::printf("Known headset attached: --device auto uses the profile %s\n",
                    table[*choice.headset].path.c_str());
    } else if (!choice.conflict.empty()) {
        std::printf("--device auto would refuse to choose: %s.\nWithout --device auto, %s\n",
                    choice.conflict.c_str(), keep.c_str());
    } else {
        std::printf(
            "No known headset attached (%zu of %zu profiles in the table list USB ids): "
            "%s\nTo add a headset: hysar-hmd --add-device VID:PID --profile NAME, with the ids "
            "listed above (configs/devices/README.md).\n",
            profiles_with_ids(table), table.size(), keep.c_str());
    }
    return 0;
}

// "2026-11-26": today's date in UTC.
std::string today_utc() {
    const std::time_t now = std::time(nullptr);
    std::tm tm{};
    gmtime_r(&now, &tm);
    char b[16];
    std::strftime(b, sizeof b, "%Y-%m-%d", &tm);
    return b;
}

// The table index of --profile's NAME (or of the table's file it names), or a usage error.
size_t profile_to_add_to(const Args& args, const std::vector<KnownHeadset>& table,
                         const std::string& local_dir) {
    if (!args.has("--profile"))
        args.fail("--add-device needs --profile NAME: the profile the headset uses");
    const std::string given = args.get("--profile", "");
    for (size_t h = 0; h < table.size(); ++h)
        if (table[h].name == given)
            return h;
    std::error_code ec;
    for (size_t h = 0; h < table.size(); ++h)
        if (std::filesystem::equivalent(given, table[h].path, ec) && !ec)
            return h;
    std::string names;
    for (const auto& h : table) names += (names.empty() ? "" : ", ") + h.name;
    args.fail("--profile '" + given + "': not a profile of the table (" + names +
              "); a headset without a profile needs its profile NAME.json in " + local_dir +
              " first (configs/devices/README.md)");
}

// --add-device VID:PID --profile NAME [--devices-dir DIR]: writes the local device entry, reads
// the table back with it, and prints the udev line for a client run without root.
int add_device(const Args& args) {
    for (const char* other : {"--list-devices", "--watch-devices", "--device"})
        if (args.has(other))
            args.fail(std::string("give --add-device or ") + other + ", not both");
    auto ids = parse_usb_pair(args.get("--add-device", ""));
    if (auto* e = std::get_if<std::string>(&ids))
        args.fail("--add-device " + *e);
    const auto [vendor, product] = std::get<std::pair<uint16_t, uint16_t>>(ids);
    const std::string local_dir = args.get("--devices-dir", kLocalDevicesDir);
    if (local_dir.empty())
        args.fail("--devices-dir: the value is empty");
    std::error_code ec;
    if (std::filesystem::exists(local_dir, ec) && !std::filesystem::is_directory(local_dir, ec))
        args.fail("--devices-dir '" + local_dir + "' is not a folder");
    const auto table =
        read_table(args, std::filesystem::is_directory(local_dir, ec) ? local_dir : "");
    const size_t h = profile_to_add_to(args, table, local_dir);
    protocol::RegisterDisplay display;
    if (auto err = load_profile(table[h].path, 1.0, &display))
        args.fail("--profile " + *err);
    for (const auto& other : table)
        for (const auto& m : other.usb)
            if (m.vendor == vendor && m.product == product)
                args.fail(
                    "--add-device " + usb_id(vendor, product) + " is in the table already: '" +
                    m.file + "' maps it to the profile " + other.name +
                    (m.file.rfind(local_dir, 0) == 0 ? " (remove that file to change it)" : ""));
    const UsbIdNames names = load_system_usb_ids();
    const std::string listed = names.name(vendor, product);
    // The profile's name and what usb.ids calls the device: the headset as the operator knows it.
    const std::string what =
        table[h].name + " (" + (listed.empty() ? usb_id(vendor, product) : listed) + ")";
    const std::string source =
        "added on site with hysar-hmd --add-device on " + today_utc() +
        (listed.empty() ? "" : "; name from " + names.file + " " + names.version);
    const WrittenEntry written =
        write_device_entry(local_dir, vendor, product, table[h].name, what, source);
    if (!written.error.empty()) {
        std::fprintf(stderr, "hysar-hmd: --add-device: %s%s\n", written.error.c_str(),
                     args.has("--devices-dir") ? ""
                                               : " (run as root, or give --devices-dir DIR and "
                                                 "pass it to --device auto too)");
        return 1;
    }
    // Read back what --device auto will read; a table that no longer loads keeps no entry.
    auto back = load_device_table(shipped_dir(args), local_dir);
    if (auto* e = std::get_if<std::string>(&back)) {
        std::filesystem::remove(written.path, ec);
        args.fail("--add-device: the table with the new entry does not load (" + *e +
                  "); nothing was added");
    }
    std::printf(
        "Added %s (%s) -> profile %s: %s\n"
        "--device auto picks the profile %s when the device is attached%s.\n"
        "For a client run without root, put this line in "
        "/etc/udev/rules.d/71-hysar-local.rules,\nthen run: udevadm control --reload && "
        "udevadm trigger\n%s\n",
        usb_id(vendor, product).c_str(), what.c_str(), table[h].name.c_str(), written.path.c_str(),
        table[h].path.c_str(),
        args.has("--devices-dir") ? (" (with --devices-dir " + local_dir + ")").c_str() : "",
        udev_rule_line(vendor, product).c_str());
    return 0;
}

int watch_devices(const Args& args, const std::vector<KnownHeadset>& table) {
    const double seconds = args.number("--watch-devices", 0, 0, 86400);
    const std::string how_long =
        seconds > 0 ? "for " + format_number(seconds) + " s" : "until SIGINT (Ctrl-C) or SIGTERM";
    const std::string local = local_dir_to_read(args);
    std::printf(
        "Watching the USB bus %s: known headsets are the %zu of %zu profiles in %s%s with "
        "USB ids; other devices are shown as they come and go.\n",
        how_long.c_str(), profiles_with_ids(table), table.size(),
        args.get("--device-table", default_device_table()).c_str(),
        local.empty() ? "" : (" and " + local).c_str());
    std::fflush(stdout);
    g_stop = 0;
    std::signal(SIGINT, on_stop_signal);
    std::signal(SIGTERM, on_stop_signal);
    size_t arrivals = 0, departures = 0;
    const UsbIdNames ids = load_system_usb_ids();
    auto report = [&](const UsbEvent& ev) {
        const auto matches = match_headsets({ev.device}, table);
        if (matches.empty()) {
            if (!ev.present)  // what was attached before the watch is not news
                std::printf("%s (not a known headset): %s\n", ev.arrived ? "arrived" : "left",
                            describe_usb(ev.device, &ids).c_str());
        } else {
            for (const auto& m : matches)
                std::printf("%s: %s  %s  profile %s\n",
                            ev.present   ? "present"
                            : ev.arrived ? "arrived"
                                         : "left",
                            headset_name(table[m.headset], m.what).c_str(),
                            describe_usb(ev.device).c_str(), table[m.headset].path.c_str());
            if (!ev.present)
                ++(ev.arrived ? arrivals : departures);
        }
        std::fflush(stdout);
    };
    auto failure = watch_usb_devices(
        seconds, [] { return g_stop != 0; }, report);
    // The process ends here: a second stop signal (timeout and a shell send one to the command
    // and then to its process group) must not kill it while it reports, as SIG_DFL would.
    std::signal(SIGINT, SIG_IGN);
    std::signal(SIGTERM, SIG_IGN);
    if (failure) {
        std::fprintf(stderr, "hysar-hmd: --watch-devices: %s\n", failure->c_str());
        return 1;
    }
    std::printf("Watch ended: %zu arrivals and %zu departures of known headsets.\n", arrivals,
                departures);
    return 0;
}

}  // namespace

std::string default_device_table() {
    const ConfigFile table = find_config("devices");
    return table.path.empty() ? config_dirs().front() + "/devices" : table.path;
}

bool wants_usb_command(const Args& args) {
    return args.has("--list-devices") || args.has("--watch-devices") || args.has("--add-device");
}

int run_usb_command(const Args& args, const std::string& configured) {
    if (args.has("--add-device"))
        return add_device(args);
    if (args.has("--list-devices") && args.has("--watch-devices"))
        args.fail("give --list-devices or --watch-devices, not both");
    const auto table = read_table(args);
    if (args.has("--watch-devices"))
        return watch_devices(args, table);
    protocol::RegisterDisplay display;
    if (auto err = load_profile(configured, 1.0, &display))
        args.fail("--profile " + *err);
    return list_devices(args, table, configured);
}

std::string choose_profile(const Args& args, const std::string& configured) {
    if (!args.has("--device")) {
        for (const char* table_option : {"--device-table", "--devices-dir"})
            if (args.has(table_option))
                args.fail(std::string(table_option) +
                          " is read by --device auto, --list-devices, --watch-devices and "
                          "--add-device only");
        return configured;
    }
    args.choice("--device", "auto", {"auto"});
    const auto table = read_table(args);
    auto listed = list_usb_devices();
    if (auto* e = std::get_if<std::string>(&listed)) {
        std::fprintf(stderr, "hysar-hmd: --device auto: %s; using the configured profile %s\n",
                     e->c_str(), configured.c_str());
        return configured;
    }
    const auto& devices = std::get<std::vector<UsbDescriptor>>(listed);
    const auto matches = match_headsets(devices, table);
    const DeviceChoice choice = choose_headset(devices, table, matches);
    if (!choice.conflict.empty())
        args.fail("--device auto: " + choice.conflict +
                  "; unplug all but one, or leave out --device auto and give --profile");
    if (!choice.headset) {
        std::fprintf(stderr,
                     "hysar-hmd: --device auto: no known headset among the %zu USB devices; "
                     "using the configured profile %s\n",
                     devices.size(), configured.c_str());
        return configured;
    }
    const std::string& chosen = table[*choice.headset].path;
    protocol::RegisterDisplay display;
    if (auto err = load_profile(chosen, 1.0, &display))
        args.fail("--device auto: the attached headset's profile " + *err);
    for (const auto& m : matches)
        if (m.headset == *choice.headset) {
            std::fprintf(stderr, "hysar-hmd: --device auto: %s (%s) -> profile %s\n",
                         headset_name(table[m.headset], m.what).c_str(),
                         describe_usb(devices[m.device]).c_str(), chosen.c_str());
            break;
        }
    return chosen;
}

}  // namespace hs::client
