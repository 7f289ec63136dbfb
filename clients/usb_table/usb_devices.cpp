// The table of known headsets and the matching: no libusb here (usb_devices.hpp).
#include "clients/usb_table/usb_devices.hpp"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <system_error>
#include <utility>

#include <nlohmann/json.hpp>

namespace hs::client {

std::string usb_id(uint16_t vendor, uint16_t product) {
    char b[16];
    std::snprintf(b, sizeof b, "%04x:%04x", unsigned(vendor), unsigned(product));
    return b;
}

namespace {

// `text` with each control character replaced by '?' and trailing blanks removed.
std::string printable(std::string text) {
    for (char& c : text)
        if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f)
            c = '?';
    while (!text.empty() && text.back() == ' ') text.pop_back();
    return text;
}

// The value of 4 hexadecimal digits at the start of `t`, or -1.
int hex4(std::string_view t) {
    if (t.size() < 4)
        return -1;
    int v = 0;
    for (char c : t.substr(0, 4)) {
        const int digit = c >= '0' && c <= '9'   ? c - '0'
                          : c >= 'a' && c <= 'f' ? c - 'a' + 10
                          : c >= 'A' && c <= 'F' ? c - 'A' + 10
                                                 : -1;
        if (digit < 0)
            return -1;
        v = v * 16 + digit;
    }
    return v;
}

// The name after an id and its blanks ("04b8  Seiko Epson Corp."), or "" when there is none.
std::string name_after(std::string_view line, size_t id_end) {
    if (line.size() <= id_end || line[id_end] != ' ')
        return "";
    const size_t start = line.find_first_not_of(' ', id_end);
    return start == std::string_view::npos ? "" : printable(std::string(line.substr(start)));
}

}  // namespace

std::string UsbIdNames::name(uint16_t vendor, uint16_t product) const {
    const auto v = vendors.find(vendor);
    const auto p = products.find(uint32_t(vendor) << 16 | product);
    if (v == vendors.end())
        return p == products.end() ? "" : p->second;
    return p == products.end() ? v->second : v->second + " " + p->second;
}

UsbIdNames parse_usb_ids(std::istream& in, const std::string& file) {
    UsbIdNames out;
    out.file = file;
    std::string line;
    int vendor = -1;  // the vendor whose products follow; -1 outside a vendor
    while (std::getline(in, line)) {
        if (!line.empty() && line.back() == '\r')
            line.pop_back();
        if (line.empty())
            continue;
        if (line[0] == '#') {
            const std::string_view tag = "# Version:";
            if (line.compare(0, tag.size(), tag) == 0 && out.version.empty())
                out.version = name_after(line, tag.size());
            continue;
        }
        if (line[0] == '\t') {
            if (vendor < 0 || (line.size() > 1 && line[1] == '\t'))
                continue;  // an interface line, or a line of a section after the vendors
            const int product = hex4(std::string_view(line).substr(1));
            const std::string name = product < 0 ? "" : name_after(line, 5);
            if (!name.empty())
                out.products.emplace(uint32_t(vendor) << 16 | uint32_t(product), name);
            continue;
        }
        const int id = hex4(line);
        const std::string name = id < 0 ? "" : name_after(line, 4);
        if (name.empty()) {
            // "C 00  ..." and the other sections after the vendors: no more vendors follow.
            if (!out.vendors.empty())
                break;
            vendor = -1;
            continue;
        }
        vendor = id;
        out.vendors.emplace(uint16_t(id), name);
    }
    return out;
}

UsbIdNames load_system_usb_ids() {
    std::vector<std::string> candidates;
    if (const char* env = std::getenv("HYSAR_USB_IDS"); env != nullptr && *env != '\0')
        candidates = {env};
    else
        candidates = {"/var/lib/usbutils/usb.ids", "/usr/share/misc/usb.ids"};
    for (const auto& path : candidates) {
        std::ifstream in(path);
        if (in)
            return parse_usb_ids(in, path);
    }
    return {};
}

std::string describe_usb(const UsbDescriptor& d, const UsbIdNames* ids) {
    char where[40];
    std::snprintf(where, sizeof where, "bus %03u address %03u", unsigned(d.bus),
                  unsigned(d.address));
    std::string s = std::string(where) + "  " + usb_id(d.vendor, d.product);
    if (!d.strings_read) {
        s += "  (strings not readable)";
    } else {
        std::string names = d.manufacturer;
        if (!d.product_name.empty())
            names += (names.empty() ? "" : " ") + d.product_name;
        if (!names.empty())
            s += "  " + names;
    }
    if (ids != nullptr)
        if (const std::string listed = ids->name(d.vendor, d.product); !listed.empty())
            s += "  [usb.ids: " + listed + "]";
    return s;
}

std::optional<uint16_t> parse_usb_id(std::string_view t) {
    if (t.size() < 3 || t.size() > 6 || t[0] != '0' || (t[1] != 'x' && t[1] != 'X'))
        return std::nullopt;
    unsigned v = 0;
    for (char c : t.substr(2)) {
        int digit = c >= '0' && c <= '9'   ? c - '0'
                    : c >= 'a' && c <= 'f' ? c - 'a' + 10
                    : c >= 'A' && c <= 'F' ? c - 'A' + 10
                                           : -1;
        if (digit < 0)
            return std::nullopt;
        v = v * 16 + unsigned(digit);
    }
    return uint16_t(v);
}

std::variant<std::pair<uint16_t, uint16_t>, std::string> parse_usb_pair(std::string_view t) {
    const std::string why = "'" + std::string(t) +
                            "': expected VENDOR:PRODUCT, 1 to 4 hexadecimal digits each, as lsusb "
                            "prints them (04b8:0d12)";
    const size_t colon = t.find(':');
    if (colon == std::string_view::npos || t.find(':', colon + 1) != std::string_view::npos)
        return why;
    std::optional<uint16_t> ids[2];
    const std::string_view sides[2] = {t.substr(0, colon), t.substr(colon + 1)};
    for (int i = 0; i < 2; ++i) {
        const std::string_view side = sides[i];
        const bool prefixed =
            side.size() > 1 && side[0] == '0' && (side[1] == 'x' || side[1] == 'X');
        ids[i] = parse_usb_id(prefixed ? std::string(side) : "0x" + std::string(side));
        if (!ids[i])
            return why;
    }
    return std::pair(*ids[0], *ids[1]);
}

namespace {

// One profile's "usb" array, or a sentence naming the entry. Each match remembers `file`.
std::variant<std::vector<UsbIdMatch>, std::string> read_usb_matches(const nlohmann::json& j,
                                                                    const std::string& file) {
    std::vector<UsbIdMatch> out;
    if (!j.contains("usb"))
        return out;
    const auto& usb = j["usb"];
    if (!usb.is_array())
        return "'usb' must be an array of { \"vendor_id\", \"product_id\", \"what\" }, not " +
               usb.dump();
    for (size_t i = 0; i < usb.size(); ++i) {
        const std::string where = "usb[" + std::to_string(i) + "]";
        const auto& e = usb[i];
        if (!e.is_object())
            return where + " must be an object, not " + e.dump();
        UsbIdMatch m;
        m.file = file;
        for (const char* key : {"vendor_id", "product_id"}) {
            if (!e.contains(key))
                return where + ": '" + key + "' is missing";
            const auto& v = e[key];
            std::optional<uint16_t> id;
            if (v.is_string())
                id = parse_usb_id(v.get<std::string>());
            if (!id)
                return where + "." + key + " = " + v.dump() +
                       ": expected \"0x\" and 1 to 4 hexadecimal digits, as lsusb shows "
                       "(\"0x04b8\")";
            (key[0] == 'v' ? m.vendor : m.product) = *id;
        }
        for (const char* key : {"what", "source"}) {
            if (!e.contains(key))
                continue;
            if (!e[key].is_string())
                return where + "." + key + " must be a string, not " + e[key].dump();
            (key[0] == 'w' ? m.what : m.source) = e[key].get<std::string>();
        }
        for (const auto& seen : out)
            if (seen.vendor == m.vendor && seen.product == m.product)
                return where + ": " + usb_id(m.vendor, m.product) + " is listed twice";
        out.push_back(std::move(m));
    }
    return out;
}

// The *.json files of `dir`, sorted by name, or a sentence.
std::variant<std::vector<std::filesystem::path>, std::string> json_files(const std::string& dir,
                                                                         const char* what) {
    std::error_code ec;
    if (!std::filesystem::is_directory(dir, ec))
        return "'" + dir + "' is not a folder of " + what;
    std::vector<std::filesystem::path> files;
    for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
        if (it->path().extension() == ".json")
            files.push_back(it->path());
    if (ec)
        return "'" + dir + "': cannot list the folder: " + ec.message();
    std::sort(files.begin(), files.end());
    return files;
}

// A file of the table as a JSON object, or a sentence naming it.
std::variant<nlohmann::json, std::string> read_object(const std::string& path, const char* what) {
    std::ifstream in(path);
    if (!in)
        return "'" + path + "': cannot open the " + what + ": " + std::strerror(errno);
    nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
    if (j.is_discarded())
        return "'" + path + "': not valid JSON";
    if (!j.is_object())
        return "'" + path + "': expected a JSON object";
    return j;
}

// The profile of `path` (its "name" and "usb"), or a sentence naming the file.
std::variant<KnownHeadset, std::string> read_profile(const nlohmann::json& j,
                                                     const std::string& path) {
    if (!j.contains("name") || !j["name"].is_string() || j["name"].get<std::string>().empty())
        return "'" + path + "': 'name' (a non-empty string) is missing";
    auto usb = read_usb_matches(j, path);
    if (auto* e = std::get_if<std::string>(&usb))
        return "'" + path + "': " + *e;
    return KnownHeadset{j["name"].get<std::string>(), path,
                        std::get<std::vector<UsbIdMatch>>(std::move(usb))};
}

// Which table entry lists each pair of ids: one device, one profile.
class IdOwners {
public:
    // A sentence when `m` (of `file`) is listed already, else nullopt (and `m` is recorded).
    std::optional<std::string> claim(const UsbIdMatch& m, const std::string& file,
                                     const std::string& profile) {
        auto [it, fresh] =
            owner_.emplace(std::pair(m.vendor, m.product), std::pair(m.file, profile));
        if (fresh)
            return std::nullopt;
        return "'" + file + "': " + usb_id(m.vendor, m.product) + " is already the USB id of '" +
               it->second.first + "' (profile " + it->second.second + "): one device, one profile";
    }

private:
    std::map<std::pair<uint16_t, uint16_t>, std::pair<std::string, std::string>> owner_;
};

std::string profile_names(const std::vector<KnownHeadset>& table) {
    std::string names;
    for (const auto& h : table) names += (names.empty() ? "" : ", ") + h.name;
    return names;
}

// Reads one file of the local folder into `table`.
std::optional<std::string> add_local_file(const std::string& path, std::vector<KnownHeadset>& table,
                                          IdOwners& owners) {
    auto read = read_object(path, "local device entry");
    if (auto* e = std::get_if<std::string>(&read))
        return *e;
    const auto& j = std::get<nlohmann::json>(read);
    if (j.contains("profile") && j.contains("name"))
        return "'" + path +
               "': give 'profile' (a device entry for a profile of the table) or 'name' (a "
               "profile of its own), not both";
    if (j.contains("name")) {
        auto h = read_profile(j, path);
        if (auto* e = std::get_if<std::string>(&h))
            return *e;
        auto& local = std::get<KnownHeadset>(h);
        for (const auto& other : table)
            if (other.name == local.name)
                return "'" + path + "': the profile '" + local.name +
                       "' is in the table already ('" + other.path +
                       "'): give this one another name, or add ids to that one with a device "
                       "entry { \"profile\": \"" +
                       local.name + "\", \"usb\": [...] }";
        for (const auto& m : local.usb)
            if (auto e = owners.claim(m, path, local.name))
                return e;
        local.local = true;
        table.push_back(std::move(local));
        return std::nullopt;
    }
    if (!j.contains("profile"))
        return "'" + path +
               "': expected a device entry { \"profile\": \"NAME\", \"usb\": [...] } (as "
               "hysar-hmd --add-device writes) or a headset profile with a \"name\"";
    if (!j["profile"].is_string() || j["profile"].get<std::string>().empty())
        return "'" + path + "': 'profile' must be a profile's name, not " + j["profile"].dump();
    const std::string name = j["profile"].get<std::string>();
    auto it = std::find_if(table.begin(), table.end(),
                           [&](const KnownHeadset& h) { return h.name == name; });
    if (it == table.end())
        return "'" + path + "': 'profile' = \"" + name +
               "\" is not a profile of the table (it has " + profile_names(table) + ")";
    auto usb = read_usb_matches(j, path);
    if (auto* e = std::get_if<std::string>(&usb))
        return "'" + path + "': " + *e;
    auto& matches = std::get<std::vector<UsbIdMatch>>(usb);
    if (matches.empty())
        return "'" + path + "': a device entry needs at least one pair of ids in 'usb'";
    for (auto& m : matches) {
        if (auto e = owners.claim(m, path, name))
            return e;
        it->usb.push_back(std::move(m));
    }
    return std::nullopt;
}

std::variant<std::vector<KnownHeadset>, std::string> load_tables(const std::string& dir,
                                                                 const std::string& local_dir) {
    auto files = json_files(dir, "headset profiles");
    if (auto* e = std::get_if<std::string>(&files))
        return *e;
    if (std::get<0>(files).empty())
        return "'" + dir + "': no headset profile (*.json) in the folder";
    std::vector<KnownHeadset> table;
    IdOwners owners;
    for (const auto& f : std::get<0>(files)) {
        const std::string path = f.string();
        auto read = read_object(path, "headset profile");
        if (auto* e = std::get_if<std::string>(&read))
            return *e;
        auto h = read_profile(std::get<nlohmann::json>(read), path);
        if (auto* e = std::get_if<std::string>(&h))
            return *e;
        for (const auto& m : std::get<KnownHeadset>(h).usb)
            if (auto e = owners.claim(m, path, std::get<KnownHeadset>(h).name))
                return *e;
        table.push_back(std::get<KnownHeadset>(std::move(h)));
    }
    if (local_dir.empty())
        return table;
    auto local = json_files(local_dir, "local device entries");
    if (auto* e = std::get_if<std::string>(&local))
        return *e;
    for (const auto& f : std::get<0>(local))
        if (auto e = add_local_file(f.string(), table, owners))
            return *e;
    return table;
}

}  // namespace

std::variant<std::vector<KnownHeadset>, std::string> load_headset_table(const std::string& dir) {
    return load_device_table(dir, "");
}

std::variant<std::vector<KnownHeadset>, std::string> load_device_table(
    const std::string& shipped_dir, const std::string& local_dir) {
    try {
        return load_tables(shipped_dir, local_dir);
    } catch (const std::exception& e) {
        return "'" + shipped_dir + "'" + (local_dir.empty() ? "" : " and '" + local_dir + "'") +
               ": " + e.what();
    }
}

std::string device_entry_file(uint16_t vendor, uint16_t product) {
    char b[32];
    std::snprintf(b, sizeof b, "usb-%04x-%04x.json", unsigned(vendor), unsigned(product));
    return b;
}

WrittenEntry write_device_entry(const std::string& dir, uint16_t vendor, uint16_t product,
                                const std::string& profile, const std::string& what,
                                const std::string& source) {
    namespace fs = std::filesystem;
    WrittenEntry out;
    out.path = (fs::path(dir) / device_entry_file(vendor, product)).string();
    try {
        std::error_code ec;
        fs::create_directories(dir, ec);
        if (ec)
            return out.error = "cannot make the folder '" + dir + "': " + ec.message(), out;
        if (fs::exists(out.path, ec))
            return out.error = "'" + out.path + "' exists already; remove it first to replace it",
                   out;
        char hex[8];
        nlohmann::json id = nlohmann::json::object();
        std::snprintf(hex, sizeof hex, "0x%04x", unsigned(vendor));
        id["vendor_id"] = hex;
        std::snprintf(hex, sizeof hex, "0x%04x", unsigned(product));
        id["product_id"] = hex;
        id["what"] = what;
        id["source"] = source;
        nlohmann::json entry = nlohmann::json::object();
        entry["profile"] = profile;
        entry["usb"] = nlohmann::json::array({id});
        const std::string tmp = out.path + ".tmp";
        {
            std::ofstream f(tmp, std::ios::trunc);
            if (!f)
                return out.error = "cannot write '" + tmp + "': " + std::strerror(errno), out;
            f << entry.dump(2) << "\n";
            f.close();
            if (!f) {
                fs::remove(tmp, ec);
                return out.error = "writing '" + tmp + "' failed", out;
            }
        }
        fs::rename(tmp, out.path, ec);
        if (ec) {
            std::error_code ignored;
            fs::remove(tmp, ignored);
            return out.error = "cannot rename '" + tmp + "' to '" + out.path + "': " + ec.message(),
                   out;
        }
    } catch (const std::exception& e) {
        out.error = "'" + out.path + "': " + e.what();
    }
    return out;
}

std::string udev_rule_line(uint16_t vendor, uint16_t product) {
    char b[200];
    std::snprintf(b, sizeof b,
                  "SUBSYSTEM==\"usb\", ENV{DEVTYPE}==\"usb_device\", ATTR{idVendor}==\"%04x\", "
                  "ATTR{idProduct}==\"%04x\", MODE=\"0660\", TAG+=\"uaccess\"",
                  unsigned(vendor), unsigned(product));
    return b;
}

std::string udev_rules(const std::vector<KnownHeadset>& table) {
    std::string s =
        "# The USB devices of the known headsets (configs/devices/*.json): the logged-in user may\n"
        "# open them (TAG+=\"uaccess\", which 73-seat-late.rules turns into an ACL), so that a\n"
        "# hysar-hmd run without root reads their names (--list-devices, --device auto).\n"
        "# Installed by `cmake --install` into lib/udev/rules.d. After installing or changing it:\n"
        "#   udevadm control --reload && udevadm trigger\n"
        "# The lines follow the shipped table: hs_usb_tests fails when they differ from it (its\n"
        "# message holds the text to put here). A headset added on site (hysar-hmd --add-device)\n"
        "# gets its own line in /etc/udev/rules.d/71-hysar-local.rules, as --add-device prints.\n";
    for (const auto& h : table) {
        if (h.usb.empty())
            continue;
        s += "\n# " + h.name + " (" + std::filesystem::path(h.path).filename().string() + ")\n";
        for (const auto& m : h.usb) {
            if (!m.what.empty())
                s += "# " + usb_id(m.vendor, m.product) + ": " + m.what + "\n";
            s += udev_rule_line(m.vendor, m.product) + "\n";
        }
    }
    return s;
}

std::vector<HeadsetMatch> match_headsets(const std::vector<UsbDescriptor>& devices,
                                         const std::vector<KnownHeadset>& table) {
    std::vector<HeadsetMatch> out;
    for (size_t d = 0; d < devices.size(); ++d)
        for (size_t h = 0; h < table.size(); ++h)
            for (const auto& m : table[h].usb)
                if (m.vendor == devices[d].vendor && m.product == devices[d].product)
                    out.push_back({d, h, m.what});
    return out;
}

DeviceChoice choose_headset(const std::vector<UsbDescriptor>& devices,
                            const std::vector<KnownHeadset>& table,
                            const std::vector<HeadsetMatch>& matches) {
    DeviceChoice c;
    std::set<size_t> profiles;
    for (const auto& m : matches) profiles.insert(m.headset);
    if (profiles.size() == 1) {
        c.headset = *profiles.begin();
    } else if (profiles.size() > 1) {
        c.conflict = std::to_string(profiles.size()) + " different known headsets are attached: ";
        std::set<size_t> named;
        for (const auto& m : matches) {
            if (!named.insert(m.headset).second)
                continue;
            const auto& d = devices[m.device];
            char where[40];
            std::snprintf(where, sizeof where, "bus %u address %u", unsigned(d.bus),
                          unsigned(d.address));
            c.conflict +=
                (named.size() > 1 ? (named.size() == profiles.size() ? " and " : ", ") : "") +
                (m.what.empty() ? table[m.headset].name : m.what) + " (" +
                usb_id(d.vendor, d.product) + ", " + where + ", profile " + table[m.headset].path +
                ")";
        }
    }
    return c;
}

}  // namespace hs::client
