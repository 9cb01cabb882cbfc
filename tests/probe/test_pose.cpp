// Probe pose: construction, rotation conventions, parsing and its errors.
#include <gtest/gtest.h>

#include "probe/pose.h"
#include "tests/test_util.h"

namespace sonotrace::probe {
namespace {

bool near(glm::dvec3 a, glm::dvec3 b, double tol = 1e-9) {
    return glm::length(a - b) < tol;
}

TEST(Pose, LookingBuildsARightHandedOrthonormalFrame) {
    const Pose p = Pose::looking({1, 2, 3}, {0, 0, -2}, {1, 0, 0.5});
    EXPECT_TRUE(near(p.axial(), {0, 0, -1}));
    EXPECT_TRUE(near(p.lateral(), {1, 0, 0}));  // hint made orthogonal to the beam
    EXPECT_TRUE(near(p.elevation(), glm::cross(p.lateral(), p.axial())));
    EXPECT_THROW(Pose::looking({0, 0, 0}, {0, 0, 1}, {0, 0, 3}), std::invalid_argument);
}

TEST(Pose, RotateTurnsAboutTheBeamTiltRocksAboutLateral) {
    const Pose p = Pose::looking({0, 0, 0}, {0, 0, 1}, {1, 0, 0});  // elevation = x cross z = -y
    const Pose r = p.rotated(90);
    EXPECT_TRUE(near(r.axial(), p.axial()));
    EXPECT_TRUE(near(glm::abs(r.lateral()), {0, 1, 0}));
    const Pose t = p.tilted(30);
    EXPECT_TRUE(near(t.lateral(), p.lateral()));
    EXPECT_NEAR(glm::degrees(std::acos(glm::dot(t.axial(), p.axial()))), 30.0, 1e-9);
}

TEST(Pose, ParseAndPrintRoundTrip) {
    const Pose p = parse_pose("at=10,-5,2.5 beam=-1,0,0 lateral=0,1,0 rotate=15 tilt=-5", "--pose");
    const Pose q = parse_pose(p.to_string(), "--pose");
    EXPECT_TRUE(near(p.position, q.position, 1e-6));
    EXPECT_TRUE(near(p.axial(), q.axial(), 1e-6));
    EXPECT_TRUE(near(p.lateral(), q.lateral(), 1e-6));
    // Default lateral: +Y unless the beam is along Y.
    EXPECT_TRUE(near(parse_pose("at=0,0,0 beam=1,0,0", "x").lateral(), {0, 1, 0}));
    EXPECT_TRUE(near(parse_pose("at=0,0,0 beam=0,-1,0", "x").lateral(), {1, 0, 0}));
}

TEST(PoseErrors, NameTheKey) {
    using test::expect_input_error;
    expect_input_error([] { parse_pose("beam=1,0,0", "--pose"); }, "--pose", "at", "required");
    expect_input_error([] { parse_pose("at=0,0,0", "--pose"); }, "--pose", "beam", "required");
    expect_input_error([] { parse_pose("at=0,0 beam=1,0,0", "--pose"); }, "--pose", "at", "three");
    expect_input_error([] { parse_pose("at=0,0,nan beam=1,0,0", "--pose"); }, "--pose", "at");
    expect_input_error([] { parse_pose("at=0,0,0 beam=0,0,0", "--pose"); }, "--pose", "beam",
                       "zero");
    expect_input_error([] { parse_pose("at=0,0,0 beam=1,0,0 lateral=2,0,0", "--pose"); }, "--pose",
                       "lateral", "parallel");
    expect_input_error([] { parse_pose("at=0,0,0 beam=1,0,0 spin=3", "--pose"); }, "--pose", "spin",
                       "unknown key");
    expect_input_error([] { parse_pose("at=0,0,0 beam=1,0,0 rotate=abc", "--pose"); }, "--pose",
                       "rotate", "degrees");
    expect_input_error([] { parse_pose("at=0,0,0 beam=1,0,0 tilt", "--pose"); }, "--pose", "tilt",
                       "key=value");
}

}  // namespace
}  // namespace sonotrace::probe
