// surgsim-web's rules without sockets or DDS, so each is unit-tested on its own: which path a request
// names and whether its token is right, what a browser's WebSocket message says (anything malformed is refused), who
// drives the tool, and how the virtual device moves towards the pose the driving page asks for (clamped to the
// device's range and slew-limited, so a key press or a wild mouse drag never makes the tool jump).
#pragma once
#include <cstdint>
#include <string>
#include <string_view>

#include "tool/trajectory.h"

namespace surgsim::web {

/// What a request's path names.
enum class Route { kPage, kAsset, kWebSocket, kStats, kNotFound };

struct Request {
  Route route = Route::kNotFound;
  std::string asset;       // for kAsset: the file name under the www folder (one of kAssets)
  std::string token;       // the `token` query parameter (empty when absent)
};

/// The files the page is made of (served from the www folder; nothing else is ever read from disk).
inline constexpr const char* kAssets[] = {"index.html", "app.js", "style.css"};

/// Parses an HTTP request target ("/ws?token=abc"). Only "/", "/index.html", "/app.js", "/style.css", "/ws" and
/// "/stats" are known; anything else (including "..") is kNotFound.
Request parse_target(std::string_view target);

/// Constant-time comparison of the token given with the server's.
bool token_matches(std::string_view given, std::string_view expected);

/// A random 128-bit token, 32 hex digits (std::random_device).
std::string random_token();

/// True for 127.0.0.0/8 and ::1 ("localhost" too).
bool is_loopback(const std::string& address);

/// MIME type of an asset by its extension.
const char* content_type(std::string_view name);

/// A message from a page (JSON text over the WebSocket).
struct ClientMessage {
  enum class Type { kTake, kRelease, kPose, kShown } type = Type::kTake;
  tool::Pose5 pose;              // kPose: the pose the page asks for (pitch, yaw, insertion, roll, jaw)
  std::uint64_t frame = 0;       // kShown: the frame number the page just displayed
};

/// Parses one message; false (with `error` saying why) for anything but {"type":"take"}, {"type":"release"},
/// {"type":"pose","pitch":P,"yaw":Y,"insertion":I,"jaw":J[,"roll":R]} with finite numbers, or
/// {"type":"shown","frame":N}.
bool parse_client_message(std::string_view text, ClientMessage& out, std::string& error);

/// The virtual device's range and speed.
struct DeviceLimits {
  double max_angle = 0.8;        // rad, |pitch| and |yaw|
  double max_insertion = 0.35;   // m (the shaft length); the minimum is 0
  double max_jaw = 1.0;          // rad
  double angle_rate = 1.0;       // rad/s
  double insertion_rate = 0.05;  // m/s
  double jaw_rate = 2.0;         // rad/s
};

/// `target` clamped to the device's range.
tool::Pose5 clamp_pose(const tool::Pose5& target, const DeviceLimits& limits);
/// One step of `dt` seconds from `current` towards `target` (clamped), each degree of freedom at most its rate.
tool::Pose5 step_towards(const tool::Pose5& current, const tool::Pose5& target, const DeviceLimits& limits, double dt);

/// Who drives the tool: at most one session at a time; the others watch.
class DriveArbiter {
 public:
  /// Session `id` asks to drive: granted when nobody drives or it already does.
  bool take(std::uint64_t id);
  /// Session `id` stops driving (closed page or "release"); no effect when it does not drive.
  void release(std::uint64_t id);
  bool drives(std::uint64_t id) const { return driver_ != 0 && driver_ == id; }
  std::uint64_t driver() const { return driver_; }  // 0: nobody

 private:
  std::uint64_t driver_ = 0;
};

}  // namespace surgsim::web
