#include "web_logic.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <random>

using namespace surgsim::tool;

namespace surgsim::web {

Request parse_target(std::string_view target) {
  Request r;
  const std::size_t q = target.find('?');
  const std::string_view path = target.substr(0, q);
  if (q != std::string_view::npos) {
    std::string_view query = target.substr(q + 1);
    while (!query.empty()) {
      const std::size_t amp = query.find('&');
      const std::string_view kv = query.substr(0, amp);
      if (kv.substr(0, 6) == "token=") r.token = std::string(kv.substr(6));
      if (amp == std::string_view::npos) break;
      query = query.substr(amp + 1);
    }
  }
  if (path == "/" || path == "/index.html") {
    r.route = Route::kPage;
  } else if (path == "/ws") {
    r.route = Route::kWebSocket;
  } else if (path == "/stats") {
    r.route = Route::kStats;
  } else {
    for (const char* a : kAssets) {
      if (path.size() > 1 && path.substr(1) == a && path != "/index.html") {
        r.route = Route::kAsset;
        r.asset = a;
      }
    }
  }
  return r;
}

bool token_matches(std::string_view given, std::string_view expected) {
  unsigned diff = given.size() == expected.size() ? 0u : 1u;
  for (std::size_t i = 0; i < expected.size(); ++i) {
    diff |= static_cast<unsigned>(static_cast<unsigned char>(i < given.size() ? given[i] : 0) ^
                                  static_cast<unsigned char>(expected[i]));
  }
  return diff == 0;
}

std::string random_token() {
  std::random_device rd;
  static const char* hex = "0123456789abcdef";
  std::string t;
  for (int i = 0; i < 4; ++i) {
    std::uint32_t v = rd();
    for (int k = 0; k < 8; ++k, v >>= 4) t += hex[v & 15u];
  }
  return t;
}

bool is_loopback(const std::string& address) {
  return address.rfind("127.", 0) == 0 || address == "::1" || address == "localhost";
}

const char* content_type(std::string_view name) {
  auto ends = [&](std::string_view ext) {
    return name.size() >= ext.size() && name.substr(name.size() - ext.size()) == ext;
  };
  if (ends(".html")) return "text/html; charset=utf-8";
  if (ends(".js")) return "text/javascript; charset=utf-8";
  if (ends(".css")) return "text/css; charset=utf-8";
  return "application/octet-stream";
}

bool parse_client_message(std::string_view text, ClientMessage& out, std::string& error) {
  const nlohmann::json j = nlohmann::json::parse(text.begin(), text.end(), nullptr, false);
  if (j.is_discarded() || !j.is_object()) {
    error = "not a JSON object";
    return false;
  }
  const auto type = j.find("type");
  if (type == j.end() || !type->is_string()) {
    error = "no \"type\" string";
    return false;
  }
  const std::string t = type->get<std::string>();
  // A finite number under `key` (or `fallback` when the key is absent and a fallback is allowed).
  auto number = [&](const char* key, double& v, bool optional) {
    const auto it = j.find(key);
    if (it == j.end()) {
      if (optional) return true;
      error = std::string("pose without \"") + key + "\"";
      return false;
    }
    if (!it->is_number() || !std::isfinite(it->get<double>())) {
      error = std::string("\"") + key + "\" is not a finite number";
      return false;
    }
    v = it->get<double>();
    return true;
  };
  if (t == "take") {
    out.type = ClientMessage::Type::kTake;
  } else if (t == "release") {
    out.type = ClientMessage::Type::kRelease;
  } else if (t == "pose") {
    out.type = ClientMessage::Type::kPose;
    out.pose = Pose5{};
    if (!number("pitch", out.pose.pitch, false) || !number("yaw", out.pose.yaw, false) ||
        !number("insertion", out.pose.insertion, false) || !number("jaw", out.pose.jaw, false) ||
        !number("roll", out.pose.roll, true)) {
      return false;
    }
  } else if (t == "shown") {
    out.type = ClientMessage::Type::kShown;
    const auto f = j.find("frame");
    if (f == j.end() || !f->is_number_unsigned()) {
      error = "\"shown\" without an unsigned \"frame\"";
      return false;
    }
    out.frame = f->get<std::uint64_t>();
  } else {
    error = "unknown type \"" + t + "\"";
    return false;
  }
  return true;
}

Pose5 clamp_pose(const Pose5& p, const DeviceLimits& l) {
  Pose5 c = p;
  c.pitch = std::clamp(p.pitch, -l.max_angle, l.max_angle);
  c.yaw = std::clamp(p.yaw, -l.max_angle, l.max_angle);
  c.insertion = std::clamp(p.insertion, 0.0, l.max_insertion);
  c.roll = std::clamp(p.roll, -M_PI, M_PI);
  c.jaw = std::clamp(p.jaw, 0.0, l.max_jaw);
  return c;
}

Pose5 step_towards(const Pose5& current, const Pose5& target, const DeviceLimits& l, double dt) {
  const Pose5 t = clamp_pose(target, l);
  auto towards = [dt](double from, double to, double rate) {
    const double step = rate * dt;
    return from + std::clamp(to - from, -step, step);
  };
  Pose5 n;
  n.pitch = towards(current.pitch, t.pitch, l.angle_rate);
  n.yaw = towards(current.yaw, t.yaw, l.angle_rate);
  n.insertion = towards(current.insertion, t.insertion, l.insertion_rate);
  n.roll = towards(current.roll, t.roll, l.angle_rate);
  n.jaw = towards(current.jaw, t.jaw, l.jaw_rate);
  return n;
}

bool DriveArbiter::take(std::uint64_t id) {
  if (driver_ != 0 && driver_ != id) return false;
  driver_ = id;
  return true;
}

void DriveArbiter::release(std::uint64_t id) {
  if (driver_ == id) driver_ = 0;
}

std::uint64_t ConnectionTable::open(std::uint64_t id) {
  where_[id] = untrusted_.insert(untrusted_.end(), id);
  if (where_.size() <= capacity_) return 0;
  // Over the capacity by this one: the oldest untrusted goes (the new one itself is untrusted, so there is one).
  const std::uint64_t victim = untrusted_.front();
  close(victim);
  return victim;
}

void ConnectionTable::trust(std::uint64_t id) {
  const auto it = where_.find(id);
  if (it == where_.end() || it->second == untrusted_.end()) return;
  untrusted_.erase(it->second);
  it->second = untrusted_.end();
}

void ConnectionTable::close(std::uint64_t id) {
  const auto it = where_.find(id);
  if (it == where_.end()) return;
  if (it->second != untrusted_.end()) untrusted_.erase(it->second);
  where_.erase(it);
}

}  // namespace surgsim::web
