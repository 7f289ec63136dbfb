// The table of known headsets and the matching: no libusb here (usb_devices.hpp).
#include "clients/usb_devices.hpp"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <utility>

#include <nlohmann/json.hpp>

namespace hs::client {

std::string usb_id(uint16_t vendor, uint16_t product) {
    char b[16];
    std::snprintf(b, sizeof b, "%04x:%04x", unsigned(vendor), unsigned(product));
    return b;
}

std::string describe_usb(const UsbDescriptor& d) {
    char where[40];
    std::snprintf(where, sizeof where, "bus %03u address %03u", unsigned(d.bus),
                  unsigned(d.address));
    std::string s = std::string(where) + "  " + usb_id(d.vendor, d.product);
    if (!d.strings_read)
        return s + "  (strings not readable)";
    std::string names = d.manufacturer;
    if (!d.product_name.empty())
        names += (names.empty() ? "" : " ") + d.product_name;
    return names.empty() ? s : s + "  " + names;
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

namespace {

// One profile's "usb" array, or a sentence naming the entry.
std::variant<std::vector<UsbIdMatch>, std::string> read_usb_matches(const nlohmann::json& j) {
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
        if (e.contains("what")) {
            if (!e["what"].is_string())
                return where + ".what must be a string, not " + e["what"].dump();
            m.what = e["what"].get<std::string>();
        }
        for (const auto& seen : out)
            if (seen.vendor == m.vendor && seen.product == m.product)
                return where + ": " + usb_id(m.vendor, m.product) + " is listed twice";
        out.push_back(std::move(m));
    }
    return out;
}

}  // namespace

std::variant<std::vector<KnownHeadset>, std::string> load_headset_table(const std::string& dir) {
    try {
        std::error_code ec;
        if (!std::filesystem::is_directory(dir, ec))
            return "'" + dir + "' is not a folder of headset profiles";
        std::vector<std::filesystem::path> files;
        for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end;
             it.increment(ec))
            if (it->path().extension() == ".json")
                files.push_back(it->path());
        if (ec)
            return "'" + dir + "': cannot list the folder: " + ec.message();
        if (files.empty())
            return "'" + dir + "': no headset profile (*.json) in the folder";
        std::sort(files.begin(), files.end());

        std::vector<KnownHeadset> table;
        std::map<std::pair<uint16_t, uint16_t>, size_t> owner;  // ids -> table index
        for (const auto& f : files) {
            const std::string path = f.string();
            std::ifstream in(path);
            if (!in)
                return "'" + path + "': cannot open the headset profile";
            const nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
            if (j.is_discarded())
                return "'" + path + "': not valid JSON";
            if (!j.is_object())
                return "'" + path + "': expected a JSON object";
            if (!j.contains("name") || !j["name"].is_string() ||
                j["name"].get<std::string>().empty())
                return "'" + path + "': 'name' (a non-empty string) is missing";
            auto usb = read_usb_matches(j);
            if (auto* e = std::get_if<std::string>(&usb))
                return "'" + path + "': " + *e;
            KnownHeadset h{j["name"].get<std::string>(), path,
                           std::get<std::vector<UsbIdMatch>>(std::move(usb))};
            for (const auto& m : h.usb) {
                auto [it, fresh] = owner.emplace(std::pair(m.vendor, m.product), table.size());
                if (!fresh)
                    return "'" + path + "': " + usb_id(m.vendor, m.product) +
                           " is already the USB id of '" + table[it->second].path +
                           "': one device, one profile";
            }
            table.push_back(std::move(h));
        }
        return table;
    } catch (const std::exception& e) {
        return "'" + dir + "': " + e.what();
    }
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
