// surgsim-web's rules without sockets or DDS, so each is unit-tested on its own: which path a request
// names and whether its token is right, what a browser's WebSocket message says (anything malformed is refused), who
// drives the tool, how the virtual device moves towards the pose the driving page asks for (clamped to the
// device's range and slew-limited, so a key press or a wild mouse drag never makes the tool jump), and which
// connection is closed first when there are too many.
#pragma once
#include <cstddef>
#include <cstdint>
#include <list>
#include <string>
#include <string_view>
#include <unordered_map>

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

/// The open connections, and which one to close when there are more than the capacity. A connection is trusted
/// once its request carried the token; the others (a request still arriving, a refusal being answered, a file of
/// the page) are closed first, the oldest first, so that connections without the token, however many, never keep
/// the token holder out: its connection is the newest untrusted one until its request is read, then trusted.
class ConnectionTable {
 public:
  explicit ConnectionTable(std::size_t capacity) : capacity_(capacity) {}
  /// Connection `id` (not 0, not open) opened. Returns the connection to close now to stay within the capacity (it
  /// is no longer in the table): 0 while there is room, else the oldest untrusted one, which is `id` itself when
  /// every other connection is trusted.
  std::uint64_t open(std::uint64_t id);
  /// Connection `id`'s request carried the token (no effect when it is not open).
  void trust(std::uint64_t id);
  /// Connection `id` closed (no effect when it is not open).
  void close(std::uint64_t id);
  /// The oldest untrusted connection (0: none).
  std::uint64_t oldest_untrusted() const { return untrusted_.empty() ? 0 : untrusted_.front(); }
  /// A new capacity, e.g. lower when the process ran out of file descriptors below the capacity; connections
  /// already open stay until the next open() (each one closes one while there are too many).
  void set_capacity(std::size_t capacity) { capacity_ = capacity; }
  std::size_t capacity() const { return capacity_; }
  std::size_t size() const { return where_.size(); }
  std::size_t trusted() const { return where_.size() - untrusted_.size(); }

 private:
  std::size_t capacity_;
  std::list<std::uint64_t> untrusted_;  // oldest first
  // id -> its place in untrusted_ (untrusted_.end() once trusted).
  std::unordered_map<std::uint64_t, std::list<std::uint64_t>::iterator> where_;
};

}  // namespace surgsim::web
