// surgsim-web's rules without sockets: paths and tokens, the page's messages (malformed ones refused with
// a reason), the virtual device's range and slew limit, one driver at a time, and which connection is closed first
// when there are too many.
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

TEST(ConnectionTable, RoomThenTheOldestUntrustedGoesFirst) {
  ConnectionTable t(3);
  EXPECT_EQ(t.open(1), 0u);
  EXPECT_EQ(t.open(2), 0u);
  EXPECT_EQ(t.open(3), 0u);
  EXPECT_EQ(t.size(), 3u);
  t.trust(1);  // 1 showed the token: never closed to make room
  EXPECT_EQ(t.trusted(), 1u);
  EXPECT_EQ(t.oldest_untrusted(), 2u);
  EXPECT_EQ(t.open(4), 2u);  // full: the oldest without the token goes, not the trusted 1 nor the new 4
  EXPECT_EQ(t.open(5), 3u);
  EXPECT_EQ(t.size(), 3u);
  t.close(4);  // closed by its end (answered, timed out)
  EXPECT_EQ(t.open(6), 0u);
  EXPECT_EQ(t.open(7), 5u);
  t.close(5);  // already gone: no effect
  t.close(99);
  EXPECT_EQ(t.size(), 3u);
  EXPECT_EQ(t.oldest_untrusted(), 6u);
}

TEST(ConnectionTable, WhenAllOthersAreTrustedTheNewOneGoes) {
  ConnectionTable t(2);
  t.open(1);
  t.open(2);
  t.trust(1);
  t.trust(2);
  t.trust(2);  // again: no effect
  EXPECT_EQ(t.oldest_untrusted(), 0u);
  EXPECT_EQ(t.open(3), 3u);
  EXPECT_EQ(t.size(), 2u);
  EXPECT_EQ(t.trusted(), 2u);
  t.close(1);  // a trusted connection closes: room again
  EXPECT_EQ(t.trusted(), 1u);
  EXPECT_EQ(t.open(4), 0u);
  t.trust(77);  // not open: no effect
  EXPECT_EQ(t.size(), 2u);
}

TEST(ConnectionTable, ALowerCapacityClosesOneAtEachOpen) {
  ConnectionTable t(4);
  for (std::uint64_t id = 1; id <= 4; ++id) t.open(id);
  t.set_capacity(2);  // e.g. the descriptors ran out below the capacity
  EXPECT_EQ(t.size(), 4u);
  EXPECT_EQ(t.open(5), 1u);
  EXPECT_EQ(t.open(6), 2u);
  EXPECT_EQ(t.size(), 4u);  // one in, one out: the table shrinks only as connections end
  t.close(3);
  t.close(4);
  EXPECT_EQ(t.open(7), 5u);
  EXPECT_EQ(t.size(), 2u);
  EXPECT_EQ(t.capacity(), 2u);
}

// A flood of connections that never show the token, and the token holder's among them: the holder's connection is
// never the one closed, whatever the order, as long as its request is read before `capacity` newer ones arrive.
TEST(ConnectionTable, AFloodNeverClosesTheTokenHolder) {
  ConnectionTable t(16);
  std::set<std::uint64_t> closed;
  std::uint64_t id = 1;
  for (int round = 0; round < 50; ++round) {
    for (int k = 0; k < 100; ++k, ++id) {
      if (const std::uint64_t v = t.open(id)) closed.insert(v);
    }
    const std::uint64_t holder = id++;
    if (const std::uint64_t v = t.open(holder)) closed.insert(v);
    for (int k = 0; k < 15; ++k, ++id) {  // fewer than the capacity arrive before the holder's request is read
      if (const std::uint64_t v = t.open(id)) closed.insert(v);
    }
    t.trust(holder);
    for (int k = 0; k < 100; ++k, ++id) {
      if (const std::uint64_t v = t.open(id)) closed.insert(v);
    }
    EXPECT_EQ(closed.count(holder), 0u) << round;
    EXPECT_EQ(t.size(), 16u);
    t.close(holder);  // answered
  }
  EXPECT_EQ(t.trusted(), 0u);
}

}  // namespace
}  // namespace surgsim::web
