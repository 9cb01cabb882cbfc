// The tracer's optimisations change nothing: the same results on 1 and 2 threads, uniform
// runs and interpolated steps, the vector stage and the scalar step, lane sampling and the
// map's, an illumination profile on or off, the interface cache on or off; and the probe
// face's capture by its geometry. Each compares against the plain path computed in the test.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <numbers>
#include <numeric>
#include <random>

#include "simulator/batch.h"
#include "simulator/interactions.h"
#include "simulator/trace_setups.h"
#include "simulator/tracer.h"
#include "tests/test_util.h"
#include "tissue/tissue_table.h"

namespace sonotrace::simulator {
namespace {

using tissue::AcousticProperties;
using tissue::Property;

// Soft tissue with a smoothed bone-like disc: most of the map is uniform blocks.
tissue::AcousticMap<2> disc_in_soft_tissue() {
    const double h = 0.25;
    tissue::PropertyMaps maps =
        homogeneous(200, 240, h, tissue::find_tissue("soft_tissue", "", "").properties);
    for (int j = 0; j < 240; ++j) {
        for (int i = 0; i < 200; ++i) {
            const double r = glm::length(glm::dvec2(i, j) * h - glm::dvec2(22, 30));
            const double blob = std::clamp((8.0 - r) / (2 * h) + 0.5, 0.0, 1.0);
            maps[Property::speed_of_sound].at(i, j) += float(blob * 600.0);
            maps[Property::density].at(i, j) += float(blob * 400.0);
        }
    }
    return tissue::AcousticMap<2>::build(maps);
}

Sources<2> fan_of_lines(int lines, int per_line) {
    Sources<2> src;
    for (int line = 0; line < lines; ++line) {
        auto beam = fan_beam({25.0f, 0.6f}, {std::sin(0.05f * float(line - lines / 2)), 1.0f}, 8.0f,
                             per_line, uint32_t(line));
        src.insert(src.end(), beam.begin(), beam.end());
    }
    return src;
}

// The disc in acoustic mode (scattering, roulette), 13 lines: first through the vector
// stage and uniform runs, then with a ring detector through the scalar step.
TEST(Tracer, ByteIdenticalOnOneAndTwoThreads) {
    const auto map = disc_in_soft_tissue();
    TraceSettings s;
    s.mode = PhysicsMode::acoustic;
    s.physics.set(Physics::scattering, true);
    s.roulette_energy = 0.2;
    const Sources<2> src = fan_of_lines(13, 31);
    for (const bool ring : {false, true}) {
        if (ring) s.ring = RingDetector{.centre = {25.0f, 30.0f}, .radius_mm = 15.0f};
        auto run = [&](int threads) {
            tbb::global_control c(tbb::global_control::max_allowed_parallelism,
                                  std::size_t(threads));
            return trace(map, src, s);
        };
        const auto a = run(1), b = run(2);
        ASSERT_GT(a.stats.reflections, 0u) << ring;
        ASSERT_GT(a.stats.scatter_events, 0u) << ring;
        ASSERT_EQ(a.echoes.size(), b.echoes.size()) << ring;
        EXPECT_TRUE(a.echoes == b.echoes) << ring;
        EXPECT_EQ(a.fluence.voxels(), b.fluence.voxels()) << ring;
        EXPECT_EQ(a.absorbed.voxels(), b.absorbed.voxels()) << ring;
        EXPECT_EQ(a.ring_profile, b.ring_profile) << ring;
        EXPECT_EQ(std::memcmp(&a.ledger, &b.ledger, sizeof a.ledger), 0) << ring;
        EXPECT_EQ(a.stats.steps, b.stats.steps) << ring;
        EXPECT_EQ(a.stats.vector_steps > 0, !ring) << ring;
    }
}

TEST(Tracer, UniformRunsDoWhatInterpolatedStepsDo) {
    // Uniform blocks skip interpolation, the interface test and refraction, with the same
    // arithmetic otherwise. Interpolating a uniform block can differ from its record in
    // the last bit (bilinear weights need not sum to exactly 1), so totals are compared
    // to 1e-5 relative, and step counts to 1e-4 (a rounding difference may move a
    // boundary crossing by one step).
    const auto map = disc_in_soft_tissue();
    ASSERT_GT(map.uniform_block_fraction(), 0.5);
    TraceSettings s;  // all physics on
    s.frequency_mhz = 3.5;
    s.echo_profile = EchoProfileSettings{1e-7, 1000};
    const Sources<2> src = fan_of_lines(8, 200);
    s.uniform_runs = false;
    const auto slow = trace(map, src, s);
    s.uniform_runs = true;
    const auto fast = trace(map, src, s);
    EXPECT_EQ(slow.stats.uniform_steps, 0u);
    EXPECT_GT(fast.stats.uniform_steps, fast.stats.steps / 2);
    EXPECT_NEAR(double(fast.stats.steps), double(slow.stats.steps),
                1e-4 * double(slow.stats.steps));
    for (const auto& [a, b, name] :
         {std::tuple{fast.ledger.absorbed, slow.ledger.absorbed, "absorbed"},
          std::tuple{fast.ledger.escaped, slow.ledger.escaped, "escaped"},
          std::tuple{fast.ledger.recorded, slow.ledger.recorded, "recorded"}})
        EXPECT_NEAR(a, b, 1e-5 * slow.ledger.injected) << name;
    EXPECT_NEAR(fast.ledger.relative_error(), 0.0, 1e-6);
    EXPECT_EQ(fast.stats.scatter_events, slow.stats.scatter_events);
    EXPECT_EQ(fast.stats.reflections, slow.stats.reflections);
    auto sum = [](const auto& v) { return std::accumulate(v.begin(), v.end(), 0.0); };
    for (const auto& [a, b, name] :
         {std::tuple{sum(fast.echo_profile.intensity), sum(slow.echo_profile.intensity), "profile"},
          std::tuple{sum(fast.echo_profile.illumination), sum(slow.echo_profile.illumination),
                     "illumination"},
          std::tuple{sum(fast.fluence.voxels()), sum(slow.fluence.voxels()), "fluence"}}) {
        EXPECT_GT(b, 0.0) << name;
        EXPECT_NEAR(a, b, 1e-5 * b) << name;
    }
}

TEST(Tracer, UniformRunsAreByteIdenticalOnOneAndTwoThreads) {
    const auto map = disc_in_soft_tissue();
    TraceSettings s;
    s.roulette_energy = 0.2;
    const Sources<2> src = fan_of_lines(13, 100);
    auto run = [&](int threads) {
        tbb::global_control c(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
        return trace(map, src, s);
    };
    const auto a = run(1), b = run(2);
    ASSERT_GT(a.stats.uniform_steps, 0u);
    EXPECT_TRUE(a.echoes == b.echoes);
    EXPECT_EQ(a.fluence.voxels(), b.fluence.voxels());
    EXPECT_EQ(a.absorbed.voxels(), b.absorbed.voxels());
    EXPECT_EQ(std::memcmp(&a.ledger, &b.ledger, sizeof a.ledger), 0);
}

// Textured tissue, as in an MRI-derived map: every texel has a gradient (smooth
// pseudo-random speed and density), with a rough bone-like disc or ball (sharp interfaces,
// reflections, total reflection), a strongly absorbing spot (beyond the attenuation
// series) and backscatter everywhere.
template <int Dim>
tissue::AcousticMap<Dim> textured_tissue(int n, double h) {
    tissue::VolumeGeometry g;
    g.dims = {n, n, Dim == 3 ? n / 2 : 1};
    g.spacing = glm::dvec3(h);
    const auto soft = tissue::find_tissue("soft_tissue", "", "").properties;
    tissue::PropertyMaps maps;
    for (tissue::Volume& f : maps.fields) f = tissue::Volume(g);
    const glm::dvec3 ball(0.5 * n * h, 0.55 * n * h, 0.25 * n * h);
    for (int k = 0; k < g.dims.z; ++k)
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i) {
                const glm::dvec3 q = glm::dvec3(i, j, k) * h;
                // untextured above y = n h / 4: uniform blocks (uniform runs)
                const double texture = q.y < 0.25 * n * h
                                           ? 0.0
                                           : std::sin(1.3 * q.x + 0.4 * q.y) * std::cos(0.9 * q.y) +
                                                 0.5 * std::sin(2.1 * q.y - 1.7 * q.x + 0.8 * q.z);
                glm::dvec3 d = q - ball;
                if (Dim == 2) d.z = 0.0;
                const double bone =
                    std::clamp((0.15 * n * h - glm::length(d)) / (2 * h) + 0.5, 0.0, 1.0);
                const double spot =
                    glm::length(q - glm::dvec3(0.3 * n * h, 0.3 * n * h, d.z)) < 1.5 ? 1.0 : 0.0;
                auto at = [&](Property p) -> float& { return maps[p].at(i, j, k); };
                at(Property::speed_of_sound) =
                    float(soft[Property::speed_of_sound] + 25.0 * texture + 1500.0 * bone);
                at(Property::density) =
                    float(soft[Property::density] + 15.0 * texture + 800.0 * bone);
                at(Property::attenuation) = float(0.6 + 0.2 * texture + 10.0 * bone + 60.0 * spot);
                at(Property::backscatter) = float(0.5 + 0.3 * texture);
                at(Property::roughness) = float(0.3 * bone);
            }
    return tissue::AcousticMap<Dim>::build(maps);
}

// The vector stage (TraceSettings::vector_steps) repeats step()'s arithmetic, so every
// particle takes the same path bit for bit; only sums over particles (the ledger, the
// echo profile) may round differently, as they add in another order.
template <int Dim>
void expect_vector_steps_take_scalar_paths(const tissue::AcousticMap<Dim>& map,
                                           const Sources<Dim>& sources) {
    TraceSettings s;  // all physics
    s.frequency_mhz = 5.0;
    s.roulette_energy = 0.05;
    s.echo_profile = EchoProfileSettings{1e-7, 600};
    s.record_paths = 1000;  // every path, vertex by vertex
    s.vector_steps = false;
    const auto scalar = trace(map, sources, s);
    s.vector_steps = true;
    const auto vector = trace(map, sources, s);
    EXPECT_EQ(scalar.stats.vector_steps, 0u);
    EXPECT_GT(vector.stats.vector_steps, (scalar.stats.steps - scalar.stats.uniform_steps) * 4 / 5);
    EXPECT_EQ(vector.stats.steps, scalar.stats.steps);
    EXPECT_GT(scalar.stats.uniform_steps, scalar.stats.steps / 20);
    EXPECT_EQ(vector.stats.uniform_steps, scalar.stats.uniform_steps);
    EXPECT_EQ(vector.stats.interface_events, scalar.stats.interface_events);
    EXPECT_EQ(vector.stats.reflections, scalar.stats.reflections);
    EXPECT_EQ(vector.stats.total_reflections, scalar.stats.total_reflections);
    EXPECT_EQ(vector.stats.scatter_events, scalar.stats.scatter_events);
    EXPECT_GT(scalar.stats.reflections, 0u);
    EXPECT_GT(scalar.stats.scatter_events, 0u);
    ASSERT_EQ(vector.paths.size(), scalar.paths.size());
    std::size_t differing = 0;
    for (std::size_t p = 0; p < scalar.paths.size(); ++p) {
        const auto &a = scalar.paths[p].vertices, &b = vector.paths[p].vertices;
        differing +=
            a.size() != b.size() || std::memcmp(a.data(), b.data(), a.size() * sizeof a[0]) != 0;
    }
    EXPECT_EQ(differing, 0u) << "of " << scalar.paths.size() << " paths";
    EXPECT_TRUE(vector.echoes == scalar.echoes);
    EXPECT_EQ(vector.fluence.voxels(), scalar.fluence.voxels());
    EXPECT_EQ(vector.absorbed.voxels(), scalar.absorbed.voxels());
    const EnergyLedger &a = scalar.ledger, &b = vector.ledger;
    for (const auto& [x, y, name] : {std::tuple{a.absorbed, b.absorbed, "absorbed"},
                                     std::tuple{a.escaped, b.escaped, "escaped"},
                                     std::tuple{a.recorded, b.recorded, "recorded"},
                                     std::tuple{a.remaining, b.remaining, "remaining"},
                                     std::tuple{a.roulette_killed, b.roulette_killed, "killed"}})
        EXPECT_NEAR(x, y, 1e-12 * a.injected) << name;
    for (const auto& [pa, pb] :
         {std::pair{&scalar.echo_profile.intensity, &vector.echo_profile.intensity},
          std::pair{&scalar.echo_profile.illumination, &vector.echo_profile.illumination}}) {
        ASSERT_EQ(pa->size(), pb->size());
        for (std::size_t i = 0; i < pa->size(); ++i)
            ASSERT_NEAR((*pa)[i], (*pb)[i], 1e-6f * std::abs((*pa)[i])) << "profile bin " << i;
    }
}

// The vector stage's samplers (sample_lanes, sample_impedance_points) and sample_impedance()
// give AcousticMap::sample()'s values bit for bit, and the uniform-block lookup the blocks
// uniform_block() finds, at random points (a tenth of them a little outside the map, where sampling
// clamps to the edge).
template <int Dim>
void expect_lane_sampling_is_the_maps(const tissue::AcousticMap<Dim>& map) {
    detail::MapView<Dim> view;
    view.texels = reinterpret_cast<const float*>(map.texels());
    view.block_records = map.block_records();
    for (int a = 0; a < Dim; ++a) {
        const auto axis = std::size_t(a);
        view.dims[axis] = map.dims()[a];
        view.inverse_spacing[axis] = map.inverse_spacing()[a];
        view.block_dims[axis] = map.block_dims()[a];
    }
    view.deposit_texels = false;
    auto batch = std::make_unique<detail::Batch<Dim>>();
    auto fields = std::make_unique<detail::LaneFields<Dim>>();
    auto points = std::make_unique<detail::ImpedancePoints<Dim>>();
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> unit(-0.05f, 1.05f);
    int uniform_lanes = 0;
    for (int round = 0; round < 40; ++round) {
        batch->count = detail::Batch<Dim>::kSize;
        for (int k = 0; k < batch->count; ++k) {
            Vec<Dim> p;
            for (int a = 0; a < Dim; ++a) p[a] = unit(rng) * map.extent_mm()[a];
            if (round % 10 != 0) p = glm::clamp(p, Vec<Dim>(0.0f), map.extent_mm());
            batch->position.set(k, p);
        }
        if (round % 10 != 0) {  // inside: the block lookup
            detail::find_uniform_blocks(view, *batch, *fields, batch->count);
            for (int k = 0; k < batch->count; ++k) {
                const auto* block = map.uniform_block(batch->position[k]);
                const int32_t record = fields->block[std::size_t(k)];
                ASSERT_EQ(block, record < 0 ? nullptr : map.uniform_record(record)) << k;
                ASSERT_EQ(fields->eligible[std::size_t(k)], record < 0 ? -1 : 0);
                uniform_lanes += record >= 0;
            }
        }
        fields->eligible.fill(-1);
        detail::sample_lanes(view, *batch, *fields, batch->count);
        // The interface lines' sampler, on a count that is not a multiple of 8.
        const int point_count = 61 - round;
        for (int k = 0; k < point_count; ++k)
            for (int a = 0; a < Dim; ++a)
                points->position[std::size_t(a)][std::size_t(k)] = batch->position[k][a];
        detail::sample_impedance_points(view, *points, point_count);
        for (int k = 0; k < batch->count; ++k) {
            const auto i = std::size_t(k);
            const auto t = map.sample(batch->position[k]);
            const auto& f = *fields;
            tissue::AcousticTexel<Dim> lane{};  // the 3D records' padding is zero too
            lane.refractive_index = f.refractive_index[i];
            lane.impedance = f.impedance[i];
            lane.attenuation = f.attenuation[i];
            lane.backscatter = f.backscatter[i];
            if constexpr (Dim == 3) lane.surface = t.surface;  // roughness: not a lane field
            for (std::size_t a = 0; a < Dim; ++a) {
                lane.grad_refractive_index[a] = f.grad_refractive_index[a][i];
                lane.grad_impedance[a] = f.grad_impedance[a][i];
            }
            ASSERT_EQ(std::memcmp(&lane, &t, sizeof lane), 0) << "lane " << k << " round " << round;
            // The interface searches' partial sample: the same bits.
            const auto z = map.sample_impedance(batch->position[k]);
            ASSERT_EQ(std::memcmp(&z.impedance, &t.impedance, sizeof(float)), 0) << k;
            ASSERT_EQ(std::memcmp(z.grad_impedance, t.grad_impedance, sizeof z.grad_impedance), 0)
                << k;
            if (k < point_count) {
                const float* point = points->sample[i].data();
                ASSERT_EQ(std::memcmp(point, &t.impedance, sizeof(float)), 0) << k;
                ASSERT_EQ(std::memcmp(point + 1, t.grad_impedance, sizeof t.grad_impedance), 0)
                    << k;
            }
        }
    }
    EXPECT_GT(uniform_lanes, 0);
}

TEST(Tracer, LaneSamplingIsTheMapsSampling) {
    expect_lane_sampling_is_the_maps(textured_tissue<2>(160, 0.25));
}
TEST(Tracer3D, LaneSamplingIsTheMapsSampling) {
    expect_lane_sampling_is_the_maps(textured_tissue<3>(64, 0.25));
}

// `lines` fans of 20 degrees from the top of textured_tissue<2>(160, 0.25) (3D: of
// textured_tissue<3>(64, 0.25)), their axes `tilt` apart (the tangent's step).
Sources<2> fans_2d(int lines, int per_line, float tilt) {
    Sources<2> src;
    for (int line = 0; line < lines; ++line) {
        auto beam = fan_beam({20.0f, 0.3f}, {tilt * float(line - lines / 2), 1.0f}, 20.0f, per_line,
                             uint32_t(line));
        src.insert(src.end(), beam.begin(), beam.end());
    }
    return src;
}
Sources<3> fans_3d(int lines, int per_line, float tilt) {
    Sources<3> src;
    for (int line = 0; line < lines; ++line) {
        auto beam = fan_beam_3d({8.0f, 0.2f, 4.0f}, {tilt * float(line - lines / 2), 1.0f, 0.05f},
                                20.0f, per_line, uint32_t(line));
        src.insert(src.end(), beam.begin(), beam.end());
    }
    return src;
}

// A convex face (radius 10 mm, 6 mm of arc either side, 3D: 3.25 mm of height either
// side) above lossless water, and particles coming straight back up at it on a grid of
// lateral offsets dx and heights dz. Geometry alone says which are captured: a particle
// meets the arc at the angle asin(dx / R), inside the aperture when R asin(|dx| / R) <= 6
// mm (|dx| <= 5.646 mm) and |dz| <= 3.25 mm. The 2D face is the 3D face's cross-section.
template <int Dim>
void expect_convex_face_captures_by_its_geometry() {
    constexpr double h = 0.5, radius = 10.0, half_width = 6.0, half_height = 3.25;
    tissue::VolumeGeometry g;
    g.dims = {60, 50, Dim == 3 ? 40 : 1};
    g.spacing = glm::dvec3(h);
    tissue::PropertyMaps maps;
    for (tissue::Volume& f : maps.fields) f = tissue::Volume(g);
    const AcousticProperties water = lossless_medium(1500, 1000);
    for (int p = 0; p < int(maps.fields.size()); ++p)
        std::fill(maps.fields[std::size_t(p)].voxels().begin(),
                  maps.fields[std::size_t(p)].voxels().end(), water[Property(p)]);
    const auto map = tissue::AcousticMap<Dim>::build(maps);
    using V = glm::vec<Dim, float>;
    ProbeFace<Dim> face;
    face.centre = V(0.0f);
    face.centre.x = 15.0f;
    face.centre.y = 5.0f;
    if constexpr (Dim == 3) face.centre.z = 10.0f;
    face.normal = V(0.0f);
    face.normal.y = 1.0f;
    face.half_width_mm = float(half_width);
    face.half_height_mm = float(half_height);
    face.radius_mm = float(radius);
    TraceSettings s = interfaces_only_settings();
    s.physics.set(Physics::attenuation, false);
    s.probe_face_3d.reset();
    if constexpr (Dim == 2)
        s.probe_face_2d = face;
    else
        s.probe_face_3d = face;
    Sources<Dim> src;
    int expected = 0;
    const std::vector<double> heights =
        Dim == 3 ? std::vector<double>{-4.0, -3.5, -3.0, -1.0, 0.0, 2.0, 3.0, 3.5, 4.0}
                 : std::vector<double>{0.0};
    for (double dx = -7.0; dx <= 7.0; dx += 0.5)
        for (double dz : heights) {
            V at(0.0f), up(0.0f);
            at.x = float(15.0 + dx);
            at.y = 20.0f;
            if constexpr (Dim == 3) at.z = float(10.0 + dz);
            up.y = -1.0f;
            src.push_back({at, up, 1.0f, uint32_t(src.size())});
            if (std::abs(dx) < radius && radius * std::asin(std::abs(dx) / radius) <= half_width &&
                std::abs(dz) <= half_height)
                ++expected;
        }
    const auto result = trace(map, src, s);
    EXPECT_EQ(int(result.stats.captured), expected) << Dim << "D, of " << src.size();
    EXPECT_GT(expected, 0);
}

TEST(Tracer, AConvexFaceCapturesByItsGeometry) {
    expect_convex_face_captures_by_its_geometry<2>();
}
TEST(Tracer3D, AConvexFaceCapturesThroughItsCylinderWithinItsHeight) {
    expect_convex_face_captures_by_its_geometry<3>();
}

// The faces built from a transducer: a convex preset's is its arc (radius and length),
// with the elements' height in 3D; the 3D face's cross-section is the 2D face.
TEST(Tracer3D, ATransducersFaceIsItsArcSweptOverTheElementHeight) {
    const probe::Transducer t = probe::find_transducer("convex", "test");
    const ProbeFace<2> flat = probe_face(t, glm::dvec2(30.0, 1.0));
    const ProbeFace<3> face = probe_face(t, glm::dvec3(30.0, 1.0, 12.0));
    EXPECT_FLOAT_EQ(flat.radius_mm, float(t.radius_mm));
    EXPECT_FLOAT_EQ(flat.half_width_mm, float(0.5 * t.elements * t.pitch_mm));
    EXPECT_EQ(face.radius_mm, flat.radius_mm);
    EXPECT_EQ(face.half_width_mm, flat.half_width_mm);
    EXPECT_FLOAT_EQ(face.half_height_mm, float(0.5 * t.elevation_aperture_mm()));
    EXPECT_EQ(glm::vec2(face.centre), flat.centre);
    EXPECT_EQ(face.centre.z, 12.0f);
    EXPECT_EQ(face.reflectivity, flat.reflectivity);
}

TEST(Tracer, VectorStepsTakeTheScalarStepsPaths) {
    expect_vector_steps_take_scalar_paths(textured_tissue<2>(160, 0.25), fans_2d(6, 150, 0.15f));
}

TEST(Tracer3D, VectorStepsTakeTheScalarStepsPaths) {
    expect_vector_steps_take_scalar_paths(textured_tissue<3>(64, 0.25), fans_3d(4, 9, 0.15f));
}

// A profile of the illumination alone (EchoProfileSettings::scattered off, as frames lit
// by their map ask) skips two sums and changes nothing else: the same illumination and
// centroids bit for bit, the same paths and echoes; the scattered sums stay zero.
template <int Dim>
void expect_illumination_alone_changes_nothing_else(const tissue::AcousticMap<Dim>& map,
                                                    const Sources<Dim>& sources) {
    TraceSettings s;
    s.frequency_mhz = 5.0;
    s.echo_profile = EchoProfileSettings{1e-7, 600};
    const auto both = trace(map, sources, s);
    s.echo_profile->scattered = false;
    const auto lit = trace(map, sources, s);
    EXPECT_EQ(lit.echo_profile.illumination, both.echo_profile.illumination);
    ASSERT_EQ(lit.echo_profile.illuminated_position.size(),
              both.echo_profile.illuminated_position.size());
    EXPECT_EQ(std::memcmp(lit.echo_profile.illuminated_position.data(),
                          both.echo_profile.illuminated_position.data(),
                          both.echo_profile.illuminated_position.size() *
                              sizeof both.echo_profile.illuminated_position[0]),
              0);
    EXPECT_TRUE(lit.echoes == both.echoes);
    EXPECT_GT(std::count_if(both.echo_profile.intensity.begin(), both.echo_profile.intensity.end(),
                            [](float v) { return v > 0.0f; }),
              100);
    ASSERT_EQ(lit.echo_profile.intensity.size(), both.echo_profile.intensity.size());
    EXPECT_TRUE(std::all_of(lit.echo_profile.intensity.begin(), lit.echo_profile.intensity.end(),
                            [](float v) { return v == 0.0f; }));
    EXPECT_EQ(lit.echo_profile.position.size(), both.echo_profile.position.size());
}

TEST(Tracer, AProfileOfTheIlluminationAloneChangesNothingElse) {
    expect_illumination_alone_changes_nothing_else(textured_tissue<2>(160, 0.25),
                                                   fans_2d(6, 150, 0.15f));
}

TEST(Tracer3D, AProfileOfTheIlluminationAloneChangesNothingElse) {
    expect_illumination_alone_changes_nothing_else(textured_tissue<3>(64, 0.25),
                                                   fans_3d(4, 9, 0.15f));
}

// The interface cache keeps what a search from a texel's centre finds; with it off every
// event searches again. Both threads share the cache and race to fill it, so equal
// results also say that no thread ever reads another texel's entry or a half-filled one.
template <int Dim>
void expect_interface_cache_changes_nothing(const tissue::AcousticMap<Dim>& map,
                                            const Sources<Dim>& sources) {
    TraceSettings s;  // all physics
    s.frequency_mhz = 5.0;
    s.record_paths = 1000;
    s.interface_cache = false;
    const auto searched = trace(map, sources, s);
    s.interface_cache = true;
    const auto cached = trace(map, sources, s);
    EXPECT_GT(searched.stats.interface_events, 100u);
    EXPECT_GT(searched.stats.reflections, 0u);
    EXPECT_EQ(cached.stats.interface_events, searched.stats.interface_events);
    EXPECT_EQ(cached.stats.reflections, searched.stats.reflections);
    EXPECT_EQ(cached.stats.steps, searched.stats.steps);
    ASSERT_EQ(cached.paths.size(), searched.paths.size());
    for (std::size_t p = 0; p < cached.paths.size(); ++p) {
        const auto &a = searched.paths[p].vertices, &b = cached.paths[p].vertices;
        ASSERT_TRUE(a.size() == b.size() &&
                    std::memcmp(a.data(), b.data(), a.size() * sizeof a[0]) == 0)
            << "path " << p;
    }
    EXPECT_TRUE(cached.echoes == searched.echoes);
    EXPECT_EQ(cached.fluence.voxels(), searched.fluence.voxels());
}

TEST(Tracer, InterfaceCacheChangesNothing) {
    expect_interface_cache_changes_nothing(textured_tissue<2>(160, 0.25), fans_2d(16, 100, 0.05f));
}

TEST(Tracer3D, InterfaceCacheChangesNothing) {
    expect_interface_cache_changes_nothing(textured_tissue<3>(64, 0.25), fans_3d(8, 9, 0.05f));
}

}  // namespace
}  // namespace sonotrace::simulator
