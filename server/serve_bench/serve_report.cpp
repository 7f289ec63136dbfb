#include "serve_bench/serve_report.hpp"

#include <algorithm>
#include <cmath>
#include <set>

#include <fmt/format.h>

#include "plot/plot.hpp"

namespace hs::bench {

using json = nlohmann::json;

namespace {

json opt(const std::optional<double>& v) {
    return v && std::isfinite(*v) ? json(*v) : json(nullptr);
}
std::optional<double> opt_of(const json& j, const char* key) {
    if (!j.contains(key) || !j[key].is_number())
        return std::nullopt;
    return j[key].get<double>();
}

std::optional<double> ratio(double served, const Baseline& b) {
    if (!b.figure || !(b.figure->per_s > 0))
        return std::nullopt;
    return served / b.figure->per_s;
}
std::optional<double> ratio_external(double served, const std::optional<LeanExternal>& l) {
    if (!l || !l->ok)
        return std::nullopt;
    return served / l->per_s;
}

std::string cell(std::optional<double> v, int precision, int width) {
    if (!v || !std::isfinite(*v))
        return fmt::format("{:>{}}", "-", width);
    return fmt::format("{:>{}.{}f}", *v, width, precision);
}

std::optional<double> stage(const ServedRow& r, std::initializer_list<const char*> names) {
    for (const char* n : names)
        if (auto it = r.stage_ms.find(n); it != r.stage_ms.end())
            return it->second;
    return std::nullopt;
}

// The smallest of 1, 1.5, 2, 2.5, 3, 4, 5, 6 or 8 times a power of ten that is at least v: four
// such steps label the axis with short, round numbers.
double nice_step(double v) {
    if (!(v > 0))
        return 1;
    const double p = std::pow(10.0, std::floor(std::log10(v)));
    for (double m : {1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0})
        if (m * p >= v * (1 - 1e-9))
            return m * p;
    return 10 * p;
}

}  // namespace

void classify_bound(ServedRow& r, double pose_rate_hz) {
    std::string top;
    double top_share = -1;
    for (const auto& [stage, share] : r.busy)
        if (share > top_share) {
            top = stage;
            top_share = share;
        }
    std::string busiest = top.empty()
                              ? std::string("no stage measured")
                              : fmt::format("busiest stage {} at {:.0f} %", top, 100 * top_share);
    for (const auto& [stage, share] : r.busy)  // the others near their limit too
        if (stage != top && share >= 0.85)
            busiest += fmt::format(", {} at {:.0f} %", stage, 100 * share);
    const double replaced =
        r.eye_layers ? double(r.layers_replaced) / double(r.eye_layers + r.layers_replaced) : 0.0;
    if (r.stereo_layers == 0) {
        r.bound = "none served";
        r.bound_why = "no stereo layer arrived in the window";
    } else if (r.per_s_slowest_headset.value_or(r.per_s_per_headset) >= 0.95 * pose_rate_hz) {
        r.bound = "poses";
        r.bound_why = fmt::format(
            "every headset got at least {:.1f} stereo layers/s of its {:.0f} poses/s; {}",
            r.per_s_slowest_headset.value_or(r.per_s_per_headset), pose_rate_hz, busiest);
    } else if (replaced > 0.05) {
        r.bound = "sockets";
        r.bound_why = fmt::format(
            "{:.0f} % of the eye layers were replaced in their socket queues by newer ones; {}",
            100 * replaced, busiest);
    } else if (top_share >= 0.85) {
        r.bound = top;
        r.bound_why = fmt::format("{}; the headsets got {:.1f} of {:.0f} layers/s", busiest,
                                  r.per_s_per_headset, pose_rate_hz);
        const auto rec = r.render_split.find("recording"), sub = r.render_split.find("submitting");
        if (top == "render_thread" && rec != r.render_split.end() && sub != r.render_split.end())
            r.bound_why += fmt::format(
                "; the render thread spent {:.0f} % of the time planning and recording, {:.0f} % "
                "submitting (waiting for a free command buffer included)",
                100 * rec->second, 100 * sub->second);
        // The GPU's busy time holds the copies of the layers into host memory.
        if (top == "gpu" && r.read_back_bytes_per_layer)
            r.bound_why += fmt::format("; its passes include reading back {:.0f} KB per eye layer",
                                       *r.read_back_bytes_per_layer / 1000);
    } else {
        // Nothing saturated: each headset has at most two frames in flight, so its rate is
        // capped near 2 / latency.
        r.bound = "latency";
        r.bound_why = fmt::format(
            "no stage over 85 % ({}); two frames in flight per headset over a p50 of {} ms",
            busiest,
            r.latency_p50_ms ? fmt::format("{:.1f}", *r.latency_p50_ms) : std::string("-"));
    }
}

std::string row_label(const ServedRow& r) {
    return r.lp_num_threads ? fmt::format("served LP_NUM_THREADS={}", *r.lp_num_threads)
                            : std::string("served");
}

json row_json(const ServedRow& r) {
    json stages = json::object();
    for (const auto& [k, v] : r.stage_ms) stages[k] = opt(v);
    json busy = json::object();
    for (const auto& [k, v] : r.busy) busy[k] = opt(v);
    json split = json::object();
    for (const auto& [k, v] : r.render_split) split[k] = opt(v);
    return {{"headsets", r.headsets},
            {"lp_num_threads", r.lp_num_threads ? json(*r.lp_num_threads) : json(nullptr)},
            {"seconds", r.seconds},
            {"warmup_s", r.warmup_s},
            {"stereo_layers", r.stereo_layers},
            {"eye_layers", r.eye_layers},
            {"stereo_per_s_total", r.per_s_total},
            {"stereo_per_s_per_headset", r.per_s_per_headset},
            {"stereo_per_s_slowest_headset", opt(r.per_s_slowest_headset)},
            {"latency_ms_p50", opt(r.latency_p50_ms)},
            {"latency_ms_p99", opt(r.latency_p99_ms)},
            {"first_layer_ms_p50", opt(r.first_layer_p50_ms)},
            {"first_layer_ms_max", opt(r.first_layer_max_ms)},
            {"stage_ms_mean", stages},
            {"bytes_per_layer", opt(r.bytes_per_layer)},
            {"read_back_bytes_per_layer", opt(r.read_back_bytes_per_layer)},
            {"shared_pass_fraction", opt(r.shared_pass_fraction)},
            {"mbps_per_headset", opt(r.mbps_per_headset)},
            {"layer_quality_mean", opt(r.layer_quality_mean)},
            {"rate_limit_hz_mean", opt(r.rate_limit_hz_mean)},
            {"cpu_ms_per_stereo_layer", opt(r.cpu_ms_per_stereo_layer)},
            {"render_thread_busy", opt(r.render_thread_busy)},
            {"interval_ms_p50", opt(r.interval_p50_ms)},
            {"interval_ms_p99", opt(r.interval_p99_ms)},
            {"busy", busy},
            {"render_thread_split", split},
            {"layers_replaced", r.layers_replaced},
            {"bound", r.bound},
            {"bound_why", r.bound_why},
            {"headsets_without_layers", r.headsets_without_layers},
            {"errors", r.errors},
            {"first_error", r.first_error}};
}

ServedRow row_of(const json& j) {
    ServedRow r;
    r.headsets = j.value("headsets", 0);
    if (j.contains("lp_num_threads") && j["lp_num_threads"].is_number_integer())
        r.lp_num_threads = j["lp_num_threads"].get<int>();
    r.seconds = j.value("seconds", 0.0);
    r.warmup_s = j.value("warmup_s", 0.0);
    r.stereo_layers = j.value("stereo_layers", uint64_t(0));
    r.eye_layers = j.value("eye_layers", uint64_t(0));
    r.per_s_total = j.value("stereo_per_s_total", 0.0);
    r.per_s_per_headset = j.value("stereo_per_s_per_headset", 0.0);
    r.per_s_slowest_headset = opt_of(j, "stereo_per_s_slowest_headset");
    r.latency_p50_ms = opt_of(j, "latency_ms_p50");
    r.latency_p99_ms = opt_of(j, "latency_ms_p99");
    r.first_layer_p50_ms = opt_of(j, "first_layer_ms_p50");
    r.first_layer_max_ms = opt_of(j, "first_layer_ms_max");
    if (j.contains("stage_ms_mean") && j["stage_ms_mean"].is_object())
        for (const auto& [k, v] : j["stage_ms_mean"].items())
            if (v.is_number())
                r.stage_ms[k] = v.get<double>();
    r.bytes_per_layer = opt_of(j, "bytes_per_layer");
    r.read_back_bytes_per_layer = opt_of(j, "read_back_bytes_per_layer");
    r.shared_pass_fraction = opt_of(j, "shared_pass_fraction");
    r.mbps_per_headset = opt_of(j, "mbps_per_headset");
    r.layer_quality_mean = opt_of(j, "layer_quality_mean");
    r.rate_limit_hz_mean = opt_of(j, "rate_limit_hz_mean");
    r.cpu_ms_per_stereo_layer = opt_of(j, "cpu_ms_per_stereo_layer");
    r.render_thread_busy = opt_of(j, "render_thread_busy");
    r.interval_p50_ms = opt_of(j, "interval_ms_p50");
    r.interval_p99_ms = opt_of(j, "interval_ms_p99");
    if (j.contains("render_thread_split") && j["render_thread_split"].is_object())
        for (const auto& [k, v] : j["render_thread_split"].items())
            if (v.is_number())
                r.render_split[k] = v.get<double>();
    if (j.contains("busy") && j["busy"].is_object())
        for (const auto& [k, v] : j["busy"].items())
            if (v.is_number())
                r.busy[k] = v.get<double>();
    r.layers_replaced = j.value("layers_replaced", uint64_t(0));
    r.bound = j.value("bound", std::string());
    r.bound_why = j.value("bound_why", std::string());
    r.headsets_without_layers = j.value("headsets_without_layers", uint64_t(0));
    r.errors = j.value("errors", uint64_t(0));
    r.first_error = j.value("first_error", std::string());
    return r;
}

std::string table(const Report& rep) {
    std::string out = fmt::format(
        "{:<26} {:>4} {:>9} {:>9} {:>9} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9} {:>9} "
        "{:>8} {:>8} {:>8} {:>8} {:<13}\n",
        "", "HMDs", "stereo/s", "/headset", "ms/stereo", "p50 ms", "p99 ms", "1st ms", "render",
        "readback", "encode", "send", "KiB/layer", "CPU ms", "x full", "x lean", "x script",
        "gap p99", "bound");
    for (const auto& b : rep.baselines) {
        const std::string label =
            b.figure ? fmt::format("{} {} tri", b.name, b.figure->triangles) : b.name;
        if (!b.figure) {
            out += fmt::format("{:<26} {}\n", label, "not measured: " + b.error);
            continue;
        }
        out += fmt::format("{:<26} {:>4} {} {:>9} {}\n", label, "-", cell(b.figure->per_s, 2, 9),
                           "-", cell(b.figure->stereo_ms, 1, 9));
    }
    if (rep.lean_external) {
        const auto& l = *rep.lean_external;
        if (l.ok)
            out += fmt::format("{:<26} {:>4} {} {:>9} {}\n", "lean script", "-",
                               cell(l.per_s, 2, 9), "-", cell(l.stereo_ms, 1, 9));
        else
            out += fmt::format("{:<26} failed: {}\n", "lean script", l.error);
    }
    for (const auto& r : rep.rows) {
        const std::optional<double> ms_per =
            r.per_s_total > 0 ? std::optional(1000.0 / r.per_s_total) : std::nullopt;
        const std::optional<double> kib =
            r.bytes_per_layer ? std::optional(*r.bytes_per_layer / 1024.0) : std::nullopt;
        out += fmt::format(
            "{:<26} {:>4} {} {} {} {} {} {} {} {} {} {} {} {} {} {} {} {} {:<13}\n", row_label(r),
            r.headsets, cell(r.per_s_total, 2, 9), cell(r.per_s_per_headset, 2, 9),
            cell(ms_per, 1, 9), cell(r.latency_p50_ms, 1, 8), cell(r.latency_p99_ms, 1, 8),
            cell(r.first_layer_p50_ms, 1, 8), cell(stage(r, {"render", "pass"}), 2, 8),
            cell(stage(r, {"readback"}), 2, 8), cell(stage(r, {"encode"}), 2, 8),
            cell(stage(r, {"send"}), 2, 8), cell(kib, 1, 9), cell(r.cpu_ms_per_stereo_layer, 1, 9),
            cell(rep.baselines.size() > 0 ? ratio(r.per_s_total, rep.baselines[0]) : std::nullopt,
                 2, 8),
            cell(rep.baselines.size() > 1 ? ratio(r.per_s_total, rep.baselines[1]) : std::nullopt,
                 2, 8),
            cell(ratio_external(r.per_s_total, rep.lean_external), 2, 8),
            cell(r.interval_p99_ms, 1, 8), r.bound.empty() ? "-" : r.bound);
    }
    out +=
        "\n"
        "stereo/s: stereo layers (both eyes of a frame) received per second; ms/stereo: the\n"
        "baselines' median per stereo pair, the served rows' 1000 / stereo/s. p50/p99: from\n"
        "sending a pose to receiving the second eye's layer rendered from it. 1st ms: a new\n"
        "headset's first stereo layer, measured alike (the median over the row's headsets; the\n"
        "largest is first_layer_ms_max in the JSON). render, readback, encode, send: the\n"
        "server's mean ms of the stage over the row, in the server's unit (per eye layer for\n"
        "the stages it counts per layer; - : it does not report the stage).\n"
        "KiB/layer: on the wire, per eye. CPU ms: this process's user + system time per\n"
        "stereo layer, which includes the in-process headset clients. x full, x lean, x script:\n"
        "served stereo/s over the full-frame, lean (64 x 32) and lean-script baselines.\n"
        "gap p99: the 99th percentile of the time between a headset's consecutive stereo\n"
        "layers (pacing; 16.7 ms at 60 Hz). bound: the stage that limited the row: poses (every\n"
        "headset got a layer per pose), sockets (queued layers replaced), render_thread, gpu,\n"
        "encoders or cores (busy >= 85 % of the window), latency (nothing saturated: two frames\n"
        "in flight per headset); the reason and every share are in the JSON (bound_why, busy).\n";
    std::set<std::string> other;
    for (const auto& r : rep.rows)
        for (const auto& [k, v] : r.stage_ms)
            if (k != "pass" && k != "render" && k != "readback" && k != "encode" && k != "send")
                other.insert(k);
    for (const auto& k : other)
        out += "the server also reports the stage '" + k + "' (stage_ms_mean in the JSON)\n";
    for (const auto& e : rep.variant_errors) out += "note: " + e + "\n";
    return out;
}

Figure plot(const Report& rep, const std::string& subtitle) {
    int most = 1;
    for (const auto& r : rep.rows) most = std::max(most, r.headsets);
    // A fixed range 0..4k (x) and 0..4s (y, s a round step) that line_plot puts nice ticks in.
    const double x_hi = 4.0 * std::ceil(most / 4.0);
    double y_max = 0;
    for (const auto& r : rep.rows) y_max = std::max(y_max, r.per_s_total);
    for (const auto& b : rep.baselines)
        if (b.figure)
            y_max = std::max(y_max, b.figure->per_s);
    if (rep.lean_external && rep.lean_external->ok)
        y_max = std::max(y_max, rep.lean_external->per_s);
    // A quarter of headroom at least: the legend sits in the top of the plot.
    const double y_hi = 4.0 * nice_step(y_max / 3.0);
    const Rgb served_colours[] = {
        {215, 60, 40}, {70, 110, 200}, {40, 150, 80}, {150, 80, 190}, {200, 140, 30}};
    std::vector<std::optional<int>> variants;
    for (const auto& r : rep.rows)
        if (std::find(variants.begin(), variants.end(), r.lp_num_threads) == variants.end())
            variants.push_back(r.lp_num_threads);
    std::vector<Series> series;
    for (size_t v = 0; v < variants.size(); ++v) {
        Series s;
        s.colour = served_colours[v % std::size(served_colours)];
        s.markers = true;
        for (const auto& r : rep.rows)
            if (r.lp_num_threads == variants[v]) {
                s.name = row_label(r);
                s.x.push_back(r.headsets);
                s.y.push_back(r.per_s_total);
                s.labels.push_back(fmt::format("{:.3g}", r.per_s_total));
            }
        series.push_back(std::move(s));
    }
    auto level = [&](const std::string& name, double per_s, Rgb c) {
        Series s{fmt::format("{} {:.3g}/s", name, per_s), {0.0, x_hi}, {per_s, per_s}, c};
        series.push_back(std::move(s));
    };
    const Rgb greys[] = {{40, 40, 40}, {140, 140, 140}};
    for (size_t i = 0; i < rep.baselines.size(); ++i)
        if (const auto& b = rep.baselines[i]; b.figure)
            level(fmt::format("{} {} tri", b.name, b.figure->triangles), b.figure->per_s,
                  greys[i % 2]);
    if (rep.lean_external && rep.lean_external->ok)
        level("lean script", rep.lean_external->per_s, {190, 150, 60});
    PlotOptions po;
    po.title = "stereo layers/s: served vs full frame";
    po.x_label = "headsets";
    po.y_label = "stereo layers/s, all headsets (" + subtitle + ")";
    po.width = 720, po.height = 420;
    po.x_lo = 0, po.x_hi = x_hi;
    po.y_lo = 0, po.y_hi = y_hi;
    return line_plot(series, po);
}

json report_json(const Report& rep) {
    json baselines = json::array();
    for (const auto& b : rep.baselines) {
        json j = {{"name", b.name}, {"tessellation", b.tessellation}};
        if (b.figure) {
            j["stereo_ms_median"] = b.figure->stereo_ms;
            j["stereo_per_s"] = b.figure->per_s;
            j["triangles"] = b.figure->triangles;
            j["frames"] = b.figure->frames;
        } else {
            j["error"] = b.error;
        }
        baselines.push_back(j);
    }
    json rows = json::array();
    for (const auto& r : rep.rows) {
        json j = row_json(r);
        j["served_over_full"] =
            opt(rep.baselines.size() > 0 ? ratio(r.per_s_total, rep.baselines[0]) : std::nullopt);
        j["served_over_lean"] =
            opt(rep.baselines.size() > 1 ? ratio(r.per_s_total, rep.baselines[1]) : std::nullopt);
        j["served_over_lean_script"] = opt(ratio_external(r.per_s_total, rep.lean_external));
        rows.push_back(j);
    }
    json out = {{"baselines", baselines}, {"rows", rows}, {"variant_errors", rep.variant_errors}};
    if (rep.lean_external) {
        const auto& l = *rep.lean_external;
        out["lean_script"] = {{"command", l.command}, {"ok", l.ok}, {"output", l.output}};
        if (l.ok) {
            out["lean_script"]["stereo_ms"] = l.stereo_ms;
            out["lean_script"]["stereo_per_s"] = l.per_s;
        } else {
            out["lean_script"]["error"] = l.error;
        }
    }
    return out;
}

}  // namespace hs::bench
