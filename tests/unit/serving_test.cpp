// Calibrated output without a GPU (calib/serving.hpp): the calibration folder `hysar serve
// --calibration` reads and every error it names, the compensation list, the headset drive's
// lookups against its double-precision reference, and the projector drive against the optical
// model it inverts.
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>

#include <gtest/gtest.h>
#include <glm/gtc/packing.hpp>
#include <nlohmann/json.hpp>

#include "calib/serving.hpp"
#include "optics/capture.hpp"

namespace hs::calib {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// A device with gamma 2.2 / 2.0 / 2.4, a few per cent of cross-talk, white about 900 DN/s over
// a black of 12: camera = M r(d) + o.
glm::dvec3 device(const glm::dvec3& d) {
    const glm::dmat3 m(880, 40, 10, 50, 900, 30, 8, 35, 860);
    return m * glm::dvec3(std::pow(d.r, 2.2), std::pow(d.g, 2.0), std::pow(d.b, 2.4)) +
           glm::dvec3(12.0);
}

ColourCalibration fitted(ColourModel model = ColourModel::kCurve) {
    std::vector<ColourSample> samples;
    for (const auto& d : colour_patch_drives()) samples.push_back({d, device(d)});
    auto c = fit_colour(samples, model);
    EXPECT_TRUE(c.ok()) << c.error().message;
    return c.ok() ? c.value() : ColourCalibration{};
}

json read(const fs::path& f) {
    std::ifstream in(f);
    return json::parse(in);
}
void write(const fs::path& f, const json& j) {
    std::ofstream(f) << j.dump(2);
}

// A calibration folder: a 64 x 40 projector, a 32 x 20 headset, optics.json.
class Folder : public ::testing::Test {
protected:
    void SetUp() override {
        dir_ = fs::temp_directory_path() / ("hysar_serving_test_" + std::to_string(::getpid()));
        fs::remove_all(dir_);
        for (auto [name, w, h] : {std::tuple{"projector", 64u, 40u}, std::tuple{"hmd", 32u, 20u}}) {
            fs::create_directories(dir_ / name);
            DeviceLut lut;
            lut.camera_width = 16, lut.camera_height = 8;
            lut.device_width = w, lut.device_height = h;
            lut.x.assign(128, NAN), lut.y.assign(128, NAN), lut.state.assign(128, 0);
            ASSERT_TRUE(save_lut(dir_ / name, lut, {}).ok());
            ASSERT_TRUE(save_colour(dir_ / name / "colour.json", fitted()).ok());
        }
        OpticalConstants c;
        c.alpha = 0.4;
        c.scene_to_signal = 1500;
        c.prop_albedo = {0.9, 0.8, 0.7};
        ASSERT_TRUE(save_optics(dir_ / "optics.json", c).ok());
    }
    void TearDown() override { fs::remove_all(dir_); }

    // The message of loading the folder, which must fail.
    std::string failure() {
        auto r = load_serving_calibration(dir_, Compensation{});
        EXPECT_FALSE(r.ok());
        return r.ok() ? std::string() : r.error().message;
    }
    fs::path dir_;
};

#define EXPECT_HAS(text, part) EXPECT_NE((text).find(part), std::string::npos) << (text)

TEST_F(Folder, LoadsWhatTheCalibrateCommandsWrite) {
    auto r = load_serving_calibration(dir_, Compensation{});
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->projector.width, 64u);
    EXPECT_EQ(r->projector.height, 40u);
    EXPECT_EQ(r->hmd.width, 32u);
    EXPECT_EQ(r->optics.alpha, 0.4);
    EXPECT_EQ(r->optics.scene_to_signal, 1500);
    EXPECT_EQ(r->optics.prop_albedo.b, 0.7);
    EXPECT_EQ(r->projector.colour.model, ColourModel::kCurve);
    EXPECT_HAS(r->summary(), "projector 64x40");
    EXPECT_HAS(r->summary(), "falloff, albedo, hmd_alpha, black_levels");
}

TEST_F(Folder, AMissingFolderOrFileIsNamed) {
    fs::remove_all(dir_ / "hmd");
    EXPECT_HAS(failure(),
               "hmd: missing; a calibration folder holds hmd/, projector/ or "
               "projectors/NAME/ for each projector, and optics.json");
    fs::remove_all(dir_);
    EXPECT_HAS(failure(), "no such calibration folder");
    std::ofstream(dir_) << "a file";
    EXPECT_HAS(failure(), "not a folder");
}

TEST_F(Folder, AMissingOpticsFileSaysHowToWriteIt) {
    fs::remove(dir_ / "optics.json");
    EXPECT_HAS(failure(),
               "optics.json: missing; write the optical constants with `hysar "
               "calibrate optics");
}

TEST_F(Folder, AFileOfAnotherKindIsNamed) {
    fs::copy_file(dir_ / "hmd" / "lut.json", dir_ / "hmd" / "colour.json",
                  fs::copy_options::overwrite_existing);
    const std::string m = failure();
    EXPECT_HAS(m, "hmd/colour.json: not a hysar-colour file");
}

TEST_F(Folder, NaNAndNonsenseNameTheFileAndField) {
    const fs::path colour = dir_ / "projector" / "colour.json";
    json j = read(colour);
    j["primaries"][1][2] = nullptr;  // how a NaN is written
    write(colour, j);
    EXPECT_HAS(failure(), "projector/colour.json: primaries[1][2] is null");
    { std::ofstream(colour) << "{\"kind\": \"hysar-colour\", \"offset\": [NaN, 0, 0]}"; }
    EXPECT_HAS(failure(), "projector/colour.json: not JSON");

    ASSERT_TRUE(save_colour(colour, fitted()).ok());
    j = read(colour);
    j["response"][0][3][0] = 0.01;  // a knot whose drive falls
    write(colour, j);
    EXPECT_HAS(failure(), "response[0][3]");

    ASSERT_TRUE(save_colour(colour, fitted()).ok());
    const fs::path lut = dir_ / "hmd" / "lut.json";
    j = read(lut);
    j["device"][0] = 31.5;
    write(lut, j);
    EXPECT_HAS(failure(), "hmd/lut.json: device[0] is 31.5, not a whole number of pixels");
    j["device"][0] = 32;
    write(lut, j);

    const fs::path optics = dir_ / "optics.json";
    const json good = read(optics);
    j = good;
    j["alpha"] = 1.5;
    write(optics, j);
    EXPECT_HAS(failure(), "optics.json: alpha is 1.5, outside (0, 1]");
    j = good;
    j["levels"]["hmd_min"] = nullptr;
    write(optics, j);
    EXPECT_HAS(failure(), "optics.json: levels.hmd_min is null");
    j = good;
    j["levels"]["projector_min"] = 5000;
    write(optics, j);
    EXPECT_HAS(failure(), "levels.projector_max (2053) must be above levels.projector_min (5000)");
    j = good;
    j.erase("prop_albedo");
    write(optics, j);
    EXPECT_HAS(failure(), "optics.json: no \"prop_albedo\"");
}

TEST_F(Folder, TheSceneAndTheHeadsetMustBeTheCalibratedSizes) {
    auto cal = load_serving_calibration(dir_, Compensation{});
    ASSERT_TRUE(cal.ok());
    scene::Scene s;
    s.projector.name = "ceiling";
    s.projector.intrinsics = {64, 40, 100, 100, 31.5, 19.5};
    EXPECT_TRUE(cal->check_scene(s).ok());
    s.projector.intrinsics.width = 1920;
    auto r = cal->check_scene(s);
    ASSERT_FALSE(r.ok());
    EXPECT_HAS(r.error().message,
               "projector/lut.json) is 64x40, the scene's projector "
               "'ceiling' is 1920x40");
    EXPECT_FALSE(cal->check_display(32, 20));
    auto why = cal->check_display(1268, 720);
    ASSERT_TRUE(why);
    EXPECT_HAS(*why, "hmd/lut.json) is 32x20 per eye, this headset's display is 1268x720");
}

// A room of several projectors: projectors/NAME/ for each, the first's projector/ optional.
TEST_F(Folder, SeveralProjectorsEachHaveTheirOwnFolder) {
    fs::create_directories(dir_ / "projectors");
    fs::rename(dir_ / "projector", dir_ / "projectors" / "front");
    fs::create_directories(dir_ / "projectors" / "rear");
    for (const char* f : {"lut.json", "lut.exr", "colour.json"})
        if (fs::exists(dir_ / "projectors" / "front" / f))
            fs::copy_file(dir_ / "projectors" / "front" / f, dir_ / "projectors" / "rear" / f);
    auto cal = load_serving_calibration(dir_, Compensation{});
    ASSERT_TRUE(cal.ok()) << cal.error().message;
    EXPECT_EQ(cal->projector.width, 0u);  // no projector/
    ASSERT_EQ(cal->named_projectors.size(), 2u);
    EXPECT_HAS(cal->summary(), "projector 'front' 64x40");
    EXPECT_HAS(cal->summary(), "projector 'rear' 64x40");
    scene::Scene s;
    s.projector.name = "front";
    s.projector.intrinsics = {64, 40, 100, 100, 31.5, 19.5};
    s.more_projectors.push_back(s.projector);
    s.more_projectors.back().name = "rear";
    EXPECT_TRUE(cal->check_scene(s).ok());
    EXPECT_EQ(cal->device_for("rear", 1), &cal->named_projectors.at("rear"));
    // A projector with no folder is named, with the folder it would need.
    s.more_projectors.push_back(s.projector);
    s.more_projectors.back().name = "side";
    auto r = cal->check_scene(s);
    ASSERT_FALSE(r.ok());
    EXPECT_HAS(r.error().message, "no folder for the scene's projector 'side'");
    EXPECT_HAS(r.error().message, "projectors/side");
    // A projector of another size names its own folder.
    s.more_projectors.pop_back();
    s.more_projectors.back().intrinsics.width = 80;
    r = cal->check_scene(s);
    ASSERT_FALSE(r.ok());
    EXPECT_HAS(r.error().message,
               "projectors/rear/lut.json) is 64x40, the scene's projector "
               "'rear' is 80x40");
    // An empty projectors/ and no projector/: nothing to drive.
    fs::remove_all(dir_ / "projectors" / "front");
    fs::remove_all(dir_ / "projectors" / "rear");
    EXPECT_HAS(failure(), "projectors: no projector folder in it");
}

TEST_F(Folder, EachProjectorsLevelsAreReadAndChecked) {
    const fs::path optics = dir_ / "optics.json";
    json j = read(optics);
    j["projectors"] = {{"rear", {{"projector_max", 1500.0}, {"projector_min", 20.0}}}};
    write(optics, j);
    auto cal = load_serving_calibration(dir_, Compensation{});
    ASSERT_TRUE(cal.ok()) << cal.error().message;
    EXPECT_EQ(cal->optics.levels_of("rear").projector_max, 1500.0);
    EXPECT_EQ(cal->optics.levels_of("rear").projector_min, 20.0);
    EXPECT_EQ(cal->optics.levels_of("front").projector_max, cal->optics.levels.projector_max);
    EXPECT_EQ(cal->drive_optics("rear").levels.projector_max, 1500.0);
    // Written back as read.
    ASSERT_TRUE(save_optics(optics, cal->optics).ok());
    EXPECT_EQ(read(optics)["projectors"]["rear"]["projector_min"], 20.0);
    j["projectors"]["rear"]["projector_min"] = 2000.0;
    write(optics, j);
    EXPECT_HAS(failure(),
               "projectors.rear.projector_max (1500) must be above projectors.rear.projector_min "
               "(2000)");
    j["projectors"]["rear"].erase("projector_min");
    write(optics, j);
    EXPECT_HAS(failure(), "no \"projectors.rear.projector_min\"");
    j["projectors"] = 3;
    write(optics, j);
    EXPECT_HAS(failure(), "projectors is not an object");
}

TEST(Compensation, ParsesListsAndNamesWhatItDoesNotKnow) {
    auto all = parse_compensation("all");
    ASSERT_TRUE(all.ok());
    EXPECT_EQ(compensation_names(*all).size(), 4u);
    auto none = parse_compensation("none");
    ASSERT_TRUE(none.ok());
    EXPECT_TRUE(compensation_names(*none).empty());
    auto two = parse_compensation("hmd_alpha,falloff");
    ASSERT_TRUE(two.ok());
    EXPECT_EQ(compensation_names(*two), (std::vector<std::string>{"falloff", "hmd_alpha"}));
    auto bad = parse_compensation("falloff,glare");
    ASSERT_FALSE(bad.ok());
    EXPECT_HAS(bad.error().message, "'glare' is not falloff, albedo, hmd_alpha or black_levels");
    EXPECT_FALSE(parse_compensation("").ok());
    EXPECT_FALSE(parse_compensation("falloff,").ok());
}

// The lookups against LayerDrive::drive (double precision, no tables) on every grey code and
// random colours: RGBA8 within one code, RGBA16F within half precision plus the table's error.
TEST(LayerDrive, LookupsAgreeWithTheDoubleReference) {
    const LayerDrive drive(fitted(), 700.0);
    std::mt19937 rng(9);
    std::uniform_int_distribution<int> code(0, 255);
    const uint32_t w = 256, h = 40;
    std::vector<uint8_t> in8(size_t(w) * h * 4), out8(in8.size(), 7);
    std::vector<uint8_t> in16(size_t(w) * h * 8), out16(in16.size(), 7);
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
            uint8_t* p = &in8[(size_t(y) * w + x) * 4];
            for (int c = 0; c < 3; ++c) p[c] = uint8_t(y == 0 ? x : code(rng));
            p[3] = (p[0] | p[1] | p[2]) ? 255 : 0;
            uint16_t hv[4];
            for (int c = 0; c < 3; ++c) hv[c] = glm::packHalf1x16(float(srgb_eotf(p[c] / 255.0)));
            hv[3] = p[3] ? glm::packHalf1x16(1.0f) : 0;
            std::memcpy(&in16[(size_t(y) * w + x) * 8], hv, 8);
        }
    drive.apply_rgba8(in8.data(), w * 4, out8.data(), w * 4, 0, 0, w, h);
    drive.apply_rgba16f(in16.data(), w * 8, out16.data(), w * 8, 0, 0, w, h);
    int worst8 = 0;
    double worst16 = 0;
    for (size_t i = 0; i < size_t(w) * h; ++i) {
        const uint8_t* p = &in8[i * 4];
        const glm::dvec3 l(srgb_eotf(p[0] / 255.0), srgb_eotf(p[1] / 255.0),
                           srgb_eotf(p[2] / 255.0));
        const glm::dvec3 d = drive.drive(l);
        uint16_t hv[4];
        std::memcpy(hv, &out16[i * 8], 8);
        for (int c = 0; c < 3; ++c) {
            worst8 =
                std::max(worst8, std::abs(int(out8[i * 4 + c]) - int(std::lround(255 * d[c]))));
            worst16 = std::max(worst16, std::fabs(glm::unpackHalf1x16(hv[c]) - srgb_eotf(d[c])));
        }
        const bool lit = out8[i * 4] | out8[i * 4 + 1] | out8[i * 4 + 2];
        EXPECT_EQ(out8[i * 4 + 3], lit ? 255 : 0) << i;
        if (!(p[0] | p[1] | p[2])) {
            EXPECT_EQ(std::vector<uint8_t>(&out8[i * 4], &out8[i * 4 + 4]),
                      std::vector<uint8_t>(4, 0));
            EXPECT_EQ(hv[0] | hv[1] | hv[2] | hv[3], 0);
        }
    }
    EXPECT_LE(worst8, 1);
    EXPECT_LT(worst16, 2e-3);
    // The drive is the colour model's: the camera sees 700 DN/s per unit radiance over black.
    const glm::dvec3 l(0.2, 0.3, 0.1);
    const glm::dvec3 seen = device(drive.drive(l)) - device(glm::dvec3(0.0));
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(seen[c] / (700 * l[c]), 1.0, 0.02) << c;
}

TEST(LayerDrive, OnlyTheRectangleIsWritten) {
    const LayerDrive drive(fitted(), 500.0);
    std::vector<uint8_t> in(8 * 4 * 4, 200), out(in.size(), 7);
    drive.apply_rgba8(in.data(), 32, out.data(), 32, 2, 1, 5, 3);
    for (uint32_t y = 0; y < 4; ++y)
        for (uint32_t x = 0; x < 8; ++x) {
            const bool inside = x >= 2 && x < 5 && y >= 1 && y < 3;
            EXPECT_EQ(out[(y * 8 + x) * 4] == 7, !inside) << x << "," << y;
        }
}

// The projector drive of a uniform frame on a prop that faces the projector everywhere: the
// light the colour model says the drive makes, through the optical model, is the target k L.
TEST_F(Folder, ProjectorDriveMakesTheTargetThroughTheColourModel) {
    scene::Scene s;
    s.projector.intrinsics = {64, 40, 100, 100, 31.5, 19.5};
    const glm::dvec3 radiance(0.4, 0.3, 0.2);
    ImageRgba32f vi = ImageRgba32f::zeros(64, 40), geometry = ImageRgba32f::zeros(64, 40);
    for (uint32_t y = 0; y < 40; ++y)
        for (uint32_t x = 0; x < 64; ++x) {
            vi.set(x, y, {float(radiance.r), float(radiance.g), float(radiance.b), 1});
            // g = 2 everywhere (g_ref 2: f = 1), but a quarter of it at the right edge.
            geometry.set(x, y, {float(x), float(y), x < 48 ? 2.0f : 0.5f, 1});
        }
    for (const char* list : {"all", "none", "falloff,albedo"}) {
        SCOPED_TRACE(list);
        auto comp = parse_compensation(list);
        ASSERT_TRUE(comp.ok());
        auto cal = load_serving_calibration(dir_, *comp);
        ASSERT_TRUE(cal.ok());
        auto d = cal->scene_drives(s, vi, geometry);
        ASSERT_TRUE(d.ok()) << d.error().message;
        EXPECT_EQ(d->scene_to_signal, 1500);
        EXPECT_EQ(d->lit(), 64u * 40u);
        EXPECT_EQ(d->projectors.front().g_ref, 2.0);
        const auto& lv = cal->optics.levels;
        const glm::dvec3 rho = comp->albedo ? cal->optics.prop_albedo : glm::dvec3(1.0);
        bool some_clip = false;  // a sample the drive cannot reach
        int checked = 0;         // channels whose light was checked
        for (uint32_t x : {10u, 60u}) {
            const glm::vec4 v = d->projector().at(x, 20);
            // The light relative to the projector's white, as its colour model predicts it.
            const glm::dvec3 white = device(glm::dvec3(1.0)) - device(glm::dvec3(0.0));
            const glm::dvec3 p = (device(glm::dvec3(v)) - device(glm::dvec3(0.0))) / white;
            const double f = comp->falloff && x >= 48 ? 0.25 : 1.0;
            for (int c = 0; c < 3; ++c) {
                const double want = 1500 * radiance[c];
                const double made =
                    comp->black_levels
                        ? f * rho[c] *
                              (lv.projector_min + (lv.projector_max - lv.projector_min) * p[c])
                        : f * rho[c] * lv.projector_max * p[c];
                if (want / (f * rho[c]) < lv.projector_max) {  // not clipped
                    EXPECT_NEAR(made / want, 1.0, 0.01) << "x " << x << " channel " << c;
                    ++checked;
                } else {
                    some_clip = true;
                }
            }
        }
        // The two samples stand for the two halves of the frame: clipped pixels are counted
        // exactly when a sample could not be reached, and some light was checked.
        EXPECT_EQ(d->clipped() > 0, some_clip) << d->clipped() << " clipped pixels";
        EXPECT_GT(checked, 0);
        // The headset: alpha k per unit radiance above its black, hmd_alpha compensated.
        const double span = comp->black_levels ? lv.hmd_max - lv.hmd_min : lv.hmd_max;
        EXPECT_NEAR(d->layers->camera_per_radiance(),
                    (lv.hmd_max - lv.hmd_min) * (comp->hmd_alpha ? 0.4 : 1.0) * 1500 / span, 1e-9);
    }
    s.projector.intrinsics.width = 65;
    EXPECT_FALSE(load_serving_calibration(dir_, {})->scene_drives(s, vi, geometry).ok());
}

// Two projectors, each through its own folder: each drive makes its weight's share of the
// target through its own colour model and its own levels, with one k for the room (the largest
// both can show); the black levels' compensation takes off each one's own black and its
// weight's share of the room light, so that together they make the target less the room light
// once.
TEST_F(Folder, EachProjectorIsDrivenForItsShareWithItsOwnLevels) {
    fs::create_directories(dir_ / "projectors");
    fs::rename(dir_ / "projector", dir_ / "projectors" / "front");
    fs::create_directories(dir_ / "projectors" / "rear");
    fs::copy(dir_ / "projectors" / "front", dir_ / "projectors" / "rear",
             fs::copy_options::recursive);
    json j = read(dir_ / "optics.json");
    j["scene_to_signal"] = 0;           // per scene: the largest both can show
    j["levels"]["environment"] = 40.0;  // the room light E, which the two must share
    j["projectors"] = {{"rear", {{"projector_max", 1200.0}, {"projector_min", 30.0}}}};
    write(dir_ / "optics.json", j);
    auto cal = load_serving_calibration(dir_, Compensation{});
    ASSERT_TRUE(cal.ok()) << cal.error().message;

    scene::Scene s;
    s.projector.name = "front";
    s.projector.intrinsics = {64, 40, 100, 100, 31.5, 19.5};
    s.more_projectors.push_back(s.projector);
    s.more_projectors.back().name = "rear";
    const glm::dvec3 radiance(0.4, 0.3, 0.2);
    ImageRgba32f geometry = ImageRgba32f::zeros(64, 40);
    std::vector<float> w_front(64 * 40), w_rear(64 * 40);
    ImageRgba32f vi_front = ImageRgba32f::zeros(64, 40), vi_rear = vi_front;
    for (uint32_t y = 0; y < 40; ++y)
        for (uint32_t x = 0; x < 64; ++x) {
            geometry.set(x, y, {float(x), float(y), 2.0f, 1});
            const float w = float(x) / 63.0f;  // the front's share grows to the right
            w_front[y * 64 + x] = w, w_rear[y * 64 + x] = 1.0f - w;
            for (auto [img, s_] : {std::pair{&vi_front, w}, std::pair{&vi_rear, 1.0f - w}})
                img->set(
                    x, y,
                    {float(radiance.r) * s_, float(radiance.g) * s_, float(radiance.b) * s_, 1});
        }
    const ProjectorShare shares[] = {{&vi_front, &geometry, &w_front},
                                     {&vi_rear, &geometry, &w_rear}};
    auto d = cal->scene_drives(s, shares);
    ASSERT_TRUE(d.ok()) << d.error().message;
    ASSERT_EQ(d->projectors.size(), 2u);
    EXPECT_EQ(d->projectors[1].name, "rear");
    EXPECT_EQ(d->projectors[1].dir, dir_ / "projectors" / "rear");
    // k: the smaller of each projector's own largest.
    double k_each[2];
    for (int p = 0; p < 2; ++p)
        k_each[p] = optics::auto_scene_to_signal(cal->drive_optics(p ? "rear" : "front"),
                                                 *shares[p].vi, geometry, 2.0);
    EXPECT_DOUBLE_EQ(d->scene_to_signal, std::min(k_each[0], k_each[1]));
    EXPECT_LT(k_each[1], k_each[0]);  // the rear is dimmer
    const glm::dvec3 rho = cal->optics.prop_albedo;
    const double room = 40.0;
    const glm::dvec3 white = device(glm::dvec3(1.0)) - device(glm::dvec3(0.0));
    for (uint32_t x : {5u, 32u, 58u}) {
        glm::dvec3 total(0.0);
        for (int p = 0; p < 2; ++p) {
            const auto lv = cal->optics.levels_of(p ? "rear" : "front");
            const glm::dvec3 rel =
                (device(glm::dvec3(d->projectors[p].drive.at(x, 20))) - device(glm::dvec3(0.0))) /
                white;
            const double w = (p ? w_rear : w_front)[20 * 64 + x];
            for (int c = 0; c < 3; ++c) {
                const double made =
                    rho[c] * (lv.projector_min + (lv.projector_max - lv.projector_min) * rel[c]);
                total[c] += made;
                // Within 0.5 % of the projector's white (a small share is a low drive, where
                // the fitted response curve is least exact).
                const double share = w * (d->scene_to_signal * radiance[c] - room);
                if (share > rho[c] * lv.projector_min) {
                    EXPECT_NEAR(made, share, 0.005 * rho[c] * lv.projector_max)
                        << "x " << x << " projector " << p << " channel " << c;
                }
            }
        }
        // Together: the target where neither is held at its black.
        if (x == 32u) {
            for (int c = 0; c < 3; ++c)
                EXPECT_NEAR(total[c] / (d->scene_to_signal * radiance[c] - room), 1.0, 0.01) << c;
        }
    }
    // One share per projector, of the projector's size.
    EXPECT_FALSE(cal->scene_drives(s, std::span(shares, 1)).ok());
    std::vector<float> short_weights(10, 0.5f);
    const ProjectorShare bad[] = {shares[0], {&vi_rear, &geometry, &short_weights}};
    auto e = cal->scene_drives(s, bad);
    ASSERT_FALSE(e.ok());
    EXPECT_HAS(e.error().message,
               "projector 'rear''s frame is 64x40, its geometry 64x40, its "
               "blend 10 weights");
}

}  // namespace
}  // namespace hs::calib
