// surgsim-web's rules without sockets: paths and tokens, the page's messages (malformed ones refused with
// a reason), the virtual device's range and slew limit, and one driver at a time.
#include "web_logic.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <set>

using namespace surgsim::tool;

namespace surgsim::web {
namespace {

TEST(WebRoutes, KnownPathsAndTokens) {
  EXPECT_EQ(parse_target("/").route, Route::kPage);
  EXPECT_EQ(parse_target("/index.html?token=a").route, Route::kPage);
  EXPECT_EQ(parse_target("/?token=abc").token, "abc");
  EXPECT_EQ(parse_target("/?x=1&token=abc&y=2").token, "abc");
  EXPECT_EQ(parse_target("/ws?token=t").route, Route::kWebSocket);
  EXPECT_EQ(parse_target("/stats?token=t").route, Route::kStats);
  const Request js = parse_target("/app.js");
  EXPECT_EQ(js.route, Route::kAsset);
  EXPECT_EQ(js.asset, "app.js");
  EXPECT_EQ(parse_target("/style.css").asset, "style.css");
  for (const char* bad : {"/nope", "/../etc/passwd", "/www/app.js", "//app.js", "/app.js/", "", "/ws/x", "app.js"}) {
    EXPECT_EQ(parse_target(bad).route, Route::kNotFound) << bad;
  }
  EXPECT_TRUE(token_matches("abcdef12", "abcdef12"));
  EXPECT_FALSE(token_matches("abcdef13", "abcdef12"));
  EXPECT_FALSE(token_matches("abcdef1", "abcdef12"));
  EXPECT_FALSE(token_matches("abcdef123", "abcdef12"));
  EXPECT_FALSE(token_matches("", "abcdef12"));
}

TEST(WebRoutes, RandomTokensAreLongAndDiffer) {
  std::set<std::string> seen;
  for (int i = 0; i < 20; ++i) {
    const std::string t = random_token();
    EXPECT_EQ(t.size(), 32u);
    EXPECT_EQ(t.find_first_not_of("0123456789abcdef"), std::string::npos);
    seen.insert(t);
  }
  EXPECT_EQ(seen.size(), 20u);
  EXPECT_TRUE(is_loopback("127.0.0.1"));
  EXPECT_TRUE(is_loopback("::1"));
  EXPECT_FALSE(is_loopback("0.0.0.0"));
  EXPECT_FALSE(is_loopback("192.168.1.2"));
}

TEST(WebMessages, ValidMessages) {
  ClientMessage m;
  std::string err;
  ASSERT_TRUE(parse_client_message(R"({"type":"take"})", m, err)) << err;
  EXPECT_EQ(m.type, ClientMessage::Type::kTake);
  ASSERT_TRUE(parse_client_message(R"({"type":"release"})", m, err)) << err;
  EXPECT_EQ(m.type, ClientMessage::Type::kRelease);
  ASSERT_TRUE(parse_client_message(R"({"type":"pose","pitch":0.1,"yaw":-0.2,"insertion":0.15,"jaw":0.5})", m, err))
      << err;
  EXPECT_EQ(m.type, ClientMessage::Type::kPose);
  EXPECT_DOUBLE_EQ(m.pose.pitch, 0.1);
  EXPECT_DOUBLE_EQ(m.pose.yaw, -0.2);
  EXPECT_DOUBLE_EQ(m.pose.insertion, 0.15);
  EXPECT_DOUBLE_EQ(m.pose.jaw, 0.5);
  EXPECT_DOUBLE_EQ(m.pose.roll, 0.0);
  ASSERT_TRUE(parse_client_message(R"({"type":"shown","frame":12345})", m, err)) << err;
  EXPECT_EQ(m.frame, 12345u);
}

TEST(WebMessages, MalformedMessagesAreRefusedWithAReason) {
  ClientMessage m;
  for (const char* bad : {"", "not json", "[1,2]", "{}", R"({"type":3})", R"({"type":"fly"})",
                          R"({"type":"pose","pitch":0,"yaw":0,"insertion":0.1})",
                          R"({"type":"pose","pitch":"0","yaw":0,"insertion":0.1,"jaw":0})",
                          R"({"type":"pose","pitch":1e999,"yaw":0,"insertion":0.1,"jaw":0})",
                          R"({"type":"pose","pitch":null,"yaw":0,"insertion":0.1,"jaw":0})",
                          R"({"type":"shown","frame":-1})", R"({"type":"shown"})", "{\"type\":\"take\""}) {
    std::string err;
    EXPECT_FALSE(parse_client_message(bad, m, err)) << bad;
    EXPECT_FALSE(err.empty()) << bad;
  }
}

TEST(VirtualDevice, ClampedAndSlewLimited) {
  DeviceLimits l;
  l.max_angle = 0.5;
  l.max_insertion = 0.3;
  l.insertion_rate = 0.05;
  l.angle_rate = 1.0;
  const Pose5 wild{10, -10, 5, 0, 9};
  const Pose5 c = clamp_pose(wild, l);
  EXPECT_DOUBLE_EQ(c.pitch, 0.5);
  EXPECT_DOUBLE_EQ(c.yaw, -0.5);
  EXPECT_DOUBLE_EQ(c.insertion, 0.3);
  EXPECT_DOUBLE_EQ(c.jaw, l.max_jaw);
  // One 5 ms step moves each degree of freedom by at most rate x dt, towards the clamped target.
  Pose5 p{0, 0, 0.1, 0, 0};
  const Pose5 n = step_towards(p, wild, l, 0.005);
  EXPECT_NEAR(n.pitch, 0.005, 1e-15);
  EXPECT_NEAR(n.yaw, -0.005, 1e-15);
  EXPECT_NEAR(n.insertion, 0.10025, 1e-15);
  // Reaches the target and stays there (no overshoot).
  for (int i = 0; i < 1000; ++i) p = step_towards(p, wild, l, 0.005);
  EXPECT_DOUBLE_EQ(p.pitch, 0.5);
  EXPECT_DOUBLE_EQ(p.insertion, 0.3);
  EXPECT_DOUBLE_EQ(step_towards(p, wild, l, 0.005).insertion, 0.3);
}

TEST(DriveArbiter, OneDriverAtATime) {
  DriveArbiter a;
  EXPECT_EQ(a.driver(), 0u);
  EXPECT_TRUE(a.take(1));
  EXPECT_TRUE(a.take(1));   // again: still it
  EXPECT_FALSE(a.take(2));  // another page cannot take the tool
  EXPECT_TRUE(a.drives(1));
  EXPECT_FALSE(a.drives(2));
  a.release(2);             // a watcher's release changes nothing
  EXPECT_TRUE(a.drives(1));
  a.release(1);             // the driving page closed
  EXPECT_EQ(a.driver(), 0u);
  EXPECT_TRUE(a.take(2));
}

}  // namespace
}  // namespace surgsim::web
