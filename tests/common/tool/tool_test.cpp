#include "tool/tool.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace surgsim::tool;

namespace surgsim {
namespace {

TEST(ToolGeometry, StraightInsertionAlongAxis) {
  ToolSpec spec;
  spec.trocar = {0, 0, 0.2};
  spec.axis = {0, 0, -1};
  Pose5 pose;
  pose.insertion = 0.1;
  const ToolGeometry g = tool_geometry(spec, pose);
  EXPECT_NEAR((g.tip - Eigen::Vector3d(0, 0, 0.1)).norm(), 0.0, 1e-12);
  EXPECT_NEAR(g.direction.z(), -1.0, 1e-12);
  EXPECT_EQ(g.point_count, spec.shaft_points);
  EXPECT_NEAR((g.points[0] - g.tip).norm(), 0.0, 1e-12);
  EXPECT_NEAR((g.points[1] - g.tip).norm(), spec.shaft_spacing, 1e-12);
}

TEST(ToolGeometry, PitchAndYawKeepTipAtInsertionDistance) {
  ToolSpec spec;
  Pose5 pose;
  pose.insertion = 0.12;
  pose.pitch = 0.3;
  pose.yaw = -0.2;
  const ToolGeometry g = tool_geometry(spec, pose);
  EXPECT_NEAR((g.tip - spec.trocar).norm(), 0.12, 1e-12);
  EXPECT_LT(g.direction.dot(spec.axis.normalized()), 1.0 - 1e-3);
}

TEST(ToolGeometry, JawOpeningSpreadsTips) {
  ToolSpec spec;
  Pose5 pose;
  pose.insertion = 0.1;
  pose.jaw = 0.0;
  const ToolGeometry closed = tool_geometry(spec, pose);
  EXPECT_NEAR((closed.jaw_tips[0] - closed.jaw_tips[1]).norm(), 0.0, 1e-12);
  pose.jaw = 0.6;
  const ToolGeometry open = tool_geometry(spec, pose);
  EXPECT_NEAR((open.jaw_tips[0] - open.jaw_tips[1]).norm(), 2 * spec.jaw_length * std::sin(0.3), 1e-12);
}

}  // namespace
}  // namespace surgsim
