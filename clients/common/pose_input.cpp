#include "clients/common/pose_input.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <vector>

#include "clients/net/args.hpp"

namespace hs::client {

namespace {

constexpr size_t kMaxLineBytes = 1024;

std::string_view trim(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r'))
        s.remove_suffix(1);
    return s;
}

}  // namespace

std::variant<std::monostate, LivePose, std::string> parse_pose_line(std::string_view line) {
    line = trim(line);
    if (line.empty() || line.front() == '#')
        return std::monostate{};
    if (line.size() > kMaxLineBytes)
        return "longer than " + std::to_string(kMaxLineBytes) + " bytes";
    // Commas or blanks between fields: each run of separators becomes one comma (two commas in
    // a run stay two, an empty field that options::read_number_list reports).
    std::string fields;
    for (size_t i = 0; i < line.size();) {
        if (line[i] != ',' && line[i] != ' ' && line[i] != '\t') {
            fields += line[i++];
            continue;
        }
        size_t commas = 0;
        for (; i < line.size() && (line[i] == ',' || line[i] == ' ' || line[i] == '\t'); ++i)
            commas += line[i] == ',';
        fields.append(std::max<size_t>(commas, 1), ',');
    }
    auto v = options::read_number_list(fields, -1e15, 1e15, 8, 9);
    if (auto* e = std::get_if<std::string>(&v))
        return *e + " (expected t_s,x,y,z,qw,qx,qy,qz[,frame_id])";
    const auto& x = std::get<std::vector<double>>(v);
    if (x[0] < 0)
        return "t_s " + format_number(x[0]) + " is negative";
    LivePose p;
    p.t_s = x[0];
    p.pose = protocol::Pose{0, {x[1], x[2], x[3]}, {x[4], x[5], x[6], x[7]}};
    if (auto bad = protocol::validate_pose(p.pose))
        return *bad;
    if (x.size() == 9) {
        if (x[8] < 0 || x[8] > 9007199254740992.0 || x[8] != std::floor(x[8]))
            return "frame_id " + format_number(x[8]) + " is not a whole number in [0, 2^53]";
        p.frame_id = uint64_t(x[8]);
    }
    return p;
}

std::variant<std::unique_ptr<PoseSource>, std::string> PoseSource::open(const std::string& spec) {
    if (spec == "-")
        return std::unique_ptr<PoseSource>(new PoseSource(0, false, "standard input"));
    if (spec.rfind("udp:", 0) != 0)
        return "'" + spec + "' is not '-' (standard input) or udp:[HOST:]PORT";
    std::string host = "127.0.0.1", port_text = spec.substr(4);
    if (const size_t colon = port_text.rfind(':'); colon != std::string::npos) {
        host = port_text.substr(0, colon);
        port_text = port_text.substr(colon + 1);
    }
    auto port = options::read_integer(port_text, 0, 65535);
    if (auto* e = std::get_if<std::string>(&port))
        return "'" + spec + "': port " + *e;
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(uint16_t(std::get<int64_t>(port)));
    if (inet_pton(AF_INET, host.c_str(), &addr.sin_addr) != 1)
        return "'" + spec + "': '" + host + "' is not a numeric IPv4 address";
    const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    if (fd < 0)
        return "'" + spec + "': socket: " + std::strerror(errno);
    socklen_t len = sizeof addr;
    if (::bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0 ||
        ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0) {
        const std::string why = std::strerror(errno);
        ::close(fd);
        return "'" + spec + "': cannot bind: " + why;
    }
    // The bound port (port 0 picks a free one): the description names it for the sender.
    return std::unique_ptr<PoseSource>(
        new PoseSource(fd, true, "UDP " + host + ":" + std::to_string(ntohs(addr.sin_port))));
}

PoseSource::PoseSource(int fd, bool udp, std::string description)
    : fd_(fd), udp_(udp), description_(std::move(description)) {
    thread_ = std::thread([this] { run(); });
}

PoseSource::~PoseSource() {
    stop_ = true;
    if (thread_.joinable())
        thread_.join();
    if (udp_)
        ::close(fd_);
}

std::optional<LivePose> PoseSource::take_latest() {
    std::lock_guard lock(mu_);
    std::optional<LivePose> out;
    out.swap(latest_);
    return out;
}

PoseSource::Counts PoseSource::counts() const {
    std::lock_guard lock(mu_);
    return counts_;
}

void PoseSource::take_line(std::string_view line) {
    auto r = parse_pose_line(line);
    std::lock_guard lock(mu_);
    const uint64_t n = ++counts_.lines;
    if (std::holds_alternative<std::monostate>(r))
        return;
    if (auto* e = std::get_if<std::string>(&r)) {
        // Reported, skipped; after 20 reports only every 1000th, so a broken sender cannot
        // flood the log.
        if (++counts_.bad <= 20 || counts_.bad % 1000 == 0)
            std::fprintf(stderr, "hysar-hmd: %s line %llu: %s (skipped; %llu bad so far)\n",
                         description_.c_str(), (unsigned long long)n, e->c_str(),
                         (unsigned long long)counts_.bad);
        return;
    }
    LivePose p = std::get<LivePose>(r);
    p.line = n;
    if (p.t_s < newest_t_) {
        if (++counts_.out_of_order <= 20)
            std::fprintf(stderr,
                         "hysar-hmd: %s line %llu: t_s %s is older than the newest pose's %s "
                         "(out of order, skipped)\n",
                         description_.c_str(), (unsigned long long)n, format_number(p.t_s).c_str(),
                         format_number(newest_t_).c_str());
        return;
    }
    newest_t_ = p.t_s;
    ++counts_.poses;
    if (latest_)
        ++counts_.superseded;
    latest_ = p;
}

void PoseSource::run() {
    std::string pending;
    std::vector<char> buf(65536);
    while (!stop_) {
        pollfd pfd{fd_, POLLIN, 0};
        const int r = ::poll(&pfd, 1, 100);
        if (r < 0 && errno == EINTR)
            continue;
        if (r <= 0)
            continue;
        const ssize_t n =
            udp_ ? ::recv(fd_, buf.data(), buf.size(), 0) : ::read(fd_, buf.data(), buf.size());
        if (n < 0 && (errno == EINTR || errno == EAGAIN))
            continue;
        if (n <= 0 && !udp_) {  // end of standard input (or an error reading it)
            if (!pending.empty())
                take_line(pending);
            finished_ = true;
            return;
        }
        if (n <= 0)
            continue;
        pending.append(buf.data(), size_t(n));
        size_t start = 0;
        for (size_t nl; (nl = pending.find('\n', start)) != std::string::npos; start = nl + 1)
            take_line(std::string_view(pending).substr(start, nl - start));
        pending.erase(0, start);
        if (udp_) {  // a datagram holds whole lines: what is left is its last line
            if (!pending.empty())
                take_line(pending);
            pending.clear();
        } else if (pending.size() > kMaxLineBytes) {
            take_line(pending);  // reported as too long
            pending.clear();
        }
    }
}

}  // namespace hs::client
