#include "web_server.h"

#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <thread>
#include <unordered_map>
#include <utility>

#include "core/clock.h"
#include "core/stats.h"
#include "web_dds.h"
#include "web_request.h"

using namespace surgsim::core;
using namespace surgsim::tool;

namespace surgsim::web {

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
namespace net = boost::asio;
using tcp = net::ip::tcp;

namespace {

std::string hex64(std::uint64_t v) {
  char b[17];
  std::snprintf(b, sizeof b, "%016llx", static_cast<unsigned long long>(v));  // NOLINT(google-runtime-int)
  return b;
}

std::string read_file(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error("cannot read " + path + " (the page's files; set --www to the folder holding them)");
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

// File descriptors the process has open now (DDS's sockets and shared memory among them).
std::size_t open_descriptors() {
  std::error_code ec;
  std::size_t n = 0;
  for (std::filesystem::directory_iterator it("/proc/self/fd", ec), end; !ec && it != end; it.increment(ec)) ++n;
  return n;
}

// Descriptors kept free below the process's limit when the connection cap is chosen: for what DDS (a participant
// discovered later) and the server itself open after start-up.
constexpr std::size_t kDescriptorReserve = 64;
// A trusted connection (its request carried the token) has this long to read its answer (the page over a slow
// SSH tunnel); the others have request_timeout_s.
constexpr auto kTrustedAnswerTimeout = std::chrono::seconds(10);
// Pauses between accept() retries after an error that closing a connection cannot cure: doubling, within these.
constexpr auto kAcceptBackoffMin = std::chrono::milliseconds(10);
constexpr auto kAcceptBackoffMax = std::chrono::milliseconds(1000);

}  // namespace

// Counters of what was served and refused (read by /stats).
struct Counters {
  std::atomic<std::uint64_t> requests{0}, pages{0}, assets{0}, stats{0}, not_found{0}, forbidden{0}, bad_request{0},
      method_not_allowed{0}, too_many_clients{0}, ws_opened{0}, ws_closed{0}, ws_oversize{0}, ws_malformed{0},
      ws_not_driver{0}, drive_refused{0}, poses{0}, commands_sent{0}, frames_to_pages{0}, frames_replaced{0};
  // Connections: accepted, closed to make room for a newer one (none carried the token), closed because the request
  // did not arrive in time, accept() errors; and, mirrored from the I/O thread's table, how many are open and the cap.
  std::atomic<std::uint64_t> accepted{0}, closed_for_room{0}, request_timeouts{0}, accept_errors{0}, open{0}, cap{0};
};

class WsSession;

struct WebServer::Impl {
  Impl(const ServerOptions& o, WebDds& d)
      : options(o),
        dds(d),
        acceptor(io),
        signals(io, SIGINT, SIGTERM),
        telemetry_timer(io),
        end_timer(io),
        accept_timer(io) {}
  void accept();
  /// A new connection: into the table (closing the oldest untrusted one when full), then its request is read.
  void admit(tcp::socket socket);
  /// Closes connection `id` to make room (it is out of the table already or is taken out).
  void close_for_room(std::uint64_t id);
  /// A connection ended (its session is gone): out of the table.
  void connection_closed(std::uint64_t id);
  /// The request of connection `id` carried the token.
  void trust(std::uint64_t id);
  /// The newest frame to every page (I/O thread; posted by the DDS frame listener).
  void broadcast_frame();
  void on_telemetry_timer();
  void command_loop();
  bool add_session(const std::shared_ptr<WsSession>& s);
  void remove_session(std::uint64_t id);
  /// A page's message (I/O thread).
  void on_message(std::uint64_t id, const std::string& text);
  std::string hello(std::uint64_t id);
  std::string stats_text();
  /// The live values (telemetry, scene, driver) shared by the telemetry messages and /stats.
  void add_live(nlohmann::json& j);

  ServerOptions options;
  WebDds& dds;
  std::map<std::string, std::string> files;  // asset name -> content
  // The open connections (I/O thread only): which one to close first when there are too many, and how to close
  // each (its session, weakly). Declared before io: sessions io still holds when it is destroyed leave these then.
  ConnectionTable connections{0};
  std::unordered_map<std::uint64_t, std::function<void()>> closers;
  std::uint64_t next_connection = 1;
  std::size_t min_connections = 0;  // the cap never comes down below this (every page and a few requests)
  net::io_context io;
  tcp::acceptor acceptor;
  net::signal_set signals;
  net::steady_timer telemetry_timer, end_timer, accept_timer;
  std::chrono::milliseconds accept_backoff{0};                 // 0: the last accept() succeeded
  std::map<std::uint64_t, std::weak_ptr<WsSession>> sessions;  // I/O thread only
  std::uint64_t next_id = 1;
  std::uint64_t last_frame = ~0ull;
  Counters counters;
  // Shared with the command thread.
  std::mutex drive_mutex;
  DriveArbiter arbiter;
  Pose5 target, current;
  std::uint64_t last_pose_ns = 0;
  std::atomic<bool> stopping{false};
  std::thread command_thread;
  // Render -> page shown delay (us), from the pages' "shown" messages.
  std::mutex delay_mutex;
  SampleRecorder delay_us{1 << 18};
  int bound_port = 0;
};

// A connection's entry in the server's table, held by its session (moved from the HTTP session to the WebSocket
// session on upgrade): its end takes the entry out, however the connection ended (answered, timed out, closed by
// either side, or the server stopped with the session still pending).
class ConnectionTicket {
 public:
  ConnectionTicket(WebServer::Impl& server, std::uint64_t id) : server_(&server), id_(id) {}
  ConnectionTicket(ConnectionTicket&& o) noexcept : server_(std::exchange(o.server_, nullptr)), id_(o.id_) {}
  ConnectionTicket(const ConnectionTicket&) = delete;
  ConnectionTicket& operator=(const ConnectionTicket&) = delete;
  ConnectionTicket& operator=(ConnectionTicket&&) = delete;
  ~ConnectionTicket() {
    if (server_) server_->connection_closed(id_);
  }
  std::uint64_t id() const { return id_; }

 private:
  WebServer::Impl* server_;
  std::uint64_t id_;
};

// One page's WebSocket.
class WsSession : public std::enable_shared_from_this<WsSession> {
 public:
  WsSession(tcp::socket&& socket, WebServer::Impl& server, std::uint64_t id, ConnectionTicket ticket)
      : ws_(std::move(socket)), server_(server), id_(id), ticket_(std::move(ticket)) {}
  std::uint64_t id() const { return id_; }

  void start(http::request<http::string_body> req) {
    ws_.read_message_max(server_.options.max_ws_message);
    ws_.set_option(websocket::stream_base::timeout::suggested(beast::role_type::server));
    ws_.async_accept(req, [self = shared_from_this()](beast::error_code ec) { self->on_accept(ec); });
  }
  void send_text(std::shared_ptr<const std::string> m) {
    pending_text_ = std::move(m);
    write_next();
  }
  void send_frame(std::shared_ptr<const std::string> m) {
    if (pending_frame_) server_.counters.frames_replaced++;  // the page is slower than the stream: newest only
    pending_frame_ = std::move(m);
    write_next();
  }
  void close() {
    beast::error_code ec;
    beast::get_lowest_layer(ws_).socket().close(ec);
  }

 private:
  void on_accept(beast::error_code ec) {
    if (ec) return;
    if (!server_.add_session(shared_from_this())) {
      ws_.async_close(websocket::close_reason(websocket::close_code::try_again_later),
                      [self = shared_from_this()](beast::error_code) {});
      return;
    }
    open_ = true;
    send_text(std::make_shared<const std::string>(server_.hello(id_)));
    read();
  }
  void read() {
    buffer_.clear();
    ws_.async_read(buffer_, [self = shared_from_this()](beast::error_code ec, std::size_t) { self->on_read(ec); });
  }
  void on_read(beast::error_code ec) {
    if (ec) {
      if (ec == websocket::error::message_too_big) server_.counters.ws_oversize++;
      open_ = false;
      server_.remove_session(id_);
      return;
    }
    if (!ws_.got_text()) {
      server_.counters.ws_malformed++;
    } else {
      server_.on_message(id_, beast::buffers_to_string(buffer_.data()));
    }
    read();
  }
  void write_next() {
    if (writing_ || !open_) return;
    if (pending_text_) {
      current_ = std::move(pending_text_);
      ws_.text(true);
    } else if (pending_frame_) {
      current_ = std::move(pending_frame_);
      ws_.binary(true);
      server_.counters.frames_to_pages++;
    } else {
      return;
    }
    writing_ = true;
    ws_.async_write(net::buffer(*current_), [self = shared_from_this()](beast::error_code ec, std::size_t) {
      self->writing_ = false;
      self->current_.reset();
      if (!ec) self->write_next();
    });
  }

  websocket::stream<beast::tcp_stream> ws_;
  beast::flat_buffer buffer_;
  WebServer::Impl& server_;
  std::uint64_t id_;
  ConnectionTicket ticket_;
  bool open_ = false, writing_ = false;
  std::shared_ptr<const std::string> pending_text_, pending_frame_, current_;
};

// One HTTP connection: one request, then a response (and close) or the upgrade to a WebSocket.
class HttpSession : public std::enable_shared_from_this<HttpSession> {
 public:
  HttpSession(tcp::socket&& socket, WebServer::Impl& server, ConnectionTicket ticket)
      : stream_(std::move(socket)), server_(server), ticket_(std::move(ticket)) {}
  void start() {
    parser_.emplace();
    limit_request_parser(*parser_);
    // The whole request within the deadline, however slowly it trickles in: a connection that never finishes its
    // headers holds a descriptor for this long at most.
    stream_.expires_after(request_timeout());
    http::async_read(stream_, buffer_, *parser_,
                     [self = shared_from_this()](beast::error_code ec, std::size_t) { self->on_read(ec); });
  }
  /// Closes the socket now (to make room for a newer connection); the pending read or write ends with an error.
  void close() { stream_.close(); }

 private:
  std::chrono::steady_clock::duration request_timeout() const {
    return std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(server_.options.request_timeout_s));
  }
  void on_read(beast::error_code ec) {
    auto& c = server_.counters;
    if (ec == beast::error::timeout) c.request_timeouts++;
    // Closed to make room (aborted), by the client before a request, or out of time: nobody to answer.
    if (ec == net::error::operation_aborted || !stream_.socket().is_open()) return;
    if (ec == http::error::end_of_stream || ec == beast::error::timeout || ec == net::error::eof) return;
    c.requests++;
    http::request<http::string_body> req;
    if (!ec) req = parser_->release();
    const RequestAnswer a = answer_request(ec, req, server_.options.token);
    // The token holder's connection is never the one closed to make room from now on, and may take its time.
    trusted_ = a.trusted;
    if (trusted_) server_.trust(ticket_.id());
    switch (a.answer) {
      case Answer::kTooLarge:
      case Answer::kMalformed:
      case Answer::kIncomplete:
        c.bad_request++;
        respond(a.answer == Answer::kTooLarge ? http::status::payload_too_large : http::status::bad_request,
                "text/plain", a.answer == Answer::kTooLarge ? "request too large\n" : "malformed request\n",
                a.version);
        return;
      case Answer::kMethodNotAllowed:
        c.method_not_allowed++;
        respond(http::status::method_not_allowed, "text/plain", "only GET\n", a.version);
        return;
      case Answer::kNotFound:
        c.not_found++;
        respond(http::status::not_found, "text/plain", "not found\n", a.version);
        return;
      case Answer::kForbidden:
        c.forbidden++;
        respond(http::status::forbidden, "text/plain",
                "forbidden: open the URL surgsim-web printed (it carries the token)\n", a.version);
        return;
      case Answer::kNotUpgrade:
        c.bad_request++;
        respond(http::status::bad_request, "text/plain", "a WebSocket upgrade is expected here\n", a.version);
        return;
      case Answer::kWebSocket: {
        const std::uint64_t connection = ticket_.id();
        auto ws =
            std::make_shared<WsSession>(stream_.release_socket(), server_, server_.next_id++, std::move(ticket_));
        server_.closers[connection] = [w = std::weak_ptr<WsSession>(ws)] {
          if (auto s = w.lock()) s->close();
        };
        ws->start(std::move(req));
        return;
      }
      case Answer::kStats:
        c.stats++;
        respond(http::status::ok, "application/json", stats_body_(), a.version);
        return;
      case Answer::kFile: {
        const bool page = a.request.route == Route::kPage;
        const std::string name = page ? "index.html" : a.request.asset;
        (page ? c.pages : c.assets)++;
        respond(http::status::ok, content_type(name), server_.files.at(name), a.version);
        return;
      }
    }
  }
  void respond(http::status status, const char* type, std::string body, unsigned version) {
    auto res = std::make_shared<http::response<http::string_body>>(status, version);
    res->set(http::field::server, "surgsim-web");
    res->set(http::field::content_type, type);
    res->set(http::field::cache_control, "no-store");
    res->keep_alive(false);
    res->body() = std::move(body);
    res->prepare_payload();
    // A refusal not read within the request's deadline is not waited for.
    stream_.expires_after(trusted_ ? std::chrono::steady_clock::duration(kTrustedAnswerTimeout) : request_timeout());
    http::async_write(stream_, *res, [self = shared_from_this(), res](beast::error_code, std::size_t) {
      beast::error_code ec;
      self->stream_.socket().shutdown(tcp::socket::shutdown_send, ec);
    });
  }

 public:
  std::function<std::string()> stats_body_;

 private:
  beast::tcp_stream stream_;
  beast::flat_buffer buffer_;
  std::optional<RequestParser> parser_;
  WebServer::Impl& server_;
  ConnectionTicket ticket_;
  bool trusted_ = false;
};

void WebServer::Impl::accept() {
  acceptor.async_accept(io, [this](beast::error_code ec, tcp::socket socket) {
    if (!ec) {
      accept_backoff = std::chrono::milliseconds(0);
      admit(std::move(socket));
      accept();
      return;
    }
    if (!acceptor.is_open() || ec == net::error::operation_aborted) return;
    counters.accept_errors++;
    // Out of file descriptors below the cap (DDS took more, or the limit was lowered): the cap comes down to the
    // connections open now, and the oldest without the token is closed so that the pending one fits; accepting goes
    // on at once, each accept() now closing one connection as the cap does.
    const bool no_descriptors =
        ec == net::error::no_descriptors || ec == boost::system::errc::too_many_files_open_in_system;
    if (no_descriptors && connections.oldest_untrusted() != 0) {
      close_for_room(connections.oldest_untrusted());
      connections.set_capacity(std::max(connections.size(), min_connections));
      counters.cap = connections.capacity();
      accept();
      return;
    }
    // Nothing to close, or another error: retry after a pause, doubling, so that a lasting error never spins.
    accept_backoff = std::clamp(2 * accept_backoff, kAcceptBackoffMin, kAcceptBackoffMax);
    accept_timer.expires_after(accept_backoff);
    accept_timer.async_wait([this](beast::error_code e) {
      if (!e) accept();
    });
  });
}

void WebServer::Impl::admit(tcp::socket socket) {
  counters.accepted++;
  const std::uint64_t id = next_connection++;
  auto s = std::make_shared<HttpSession>(std::move(socket), *this, ConnectionTicket(*this, id));
  closers[id] = [w = std::weak_ptr<HttpSession>(s)] {
    if (auto p = w.lock()) p->close();
  };
  const std::uint64_t victim = connections.open(id);
  if (victim != 0) close_for_room(victim);
  counters.open = connections.size();
  if (victim == id) return;  // every other connection is trusted: this one goes (its socket closes with `s`)
  s->stats_body_ = [this] { return stats_text(); };
  s->start();
}

void WebServer::Impl::close_for_room(std::uint64_t id) {
  connections.close(id);
  counters.closed_for_room++;
  const auto it = closers.find(id);
  if (it == closers.end()) return;
  const std::function<void()> close = std::move(it->second);
  closers.erase(it);
  close();  // the descriptor is free now; the session ends when its aborted operation's handler runs
}

void WebServer::Impl::connection_closed(std::uint64_t id) {
  connections.close(id);
  closers.erase(id);
  counters.open = connections.size();
}

void WebServer::Impl::trust(std::uint64_t id) { connections.trust(id); }

bool WebServer::Impl::add_session(const std::shared_ptr<WsSession>& s) {
  std::size_t open = 0;
  for (auto it = sessions.begin(); it != sessions.end();) {
    if (it->second.expired()) {
      it = sessions.erase(it);
    } else {
      ++open;
      ++it;
    }
  }
  if (open >= static_cast<std::size_t>(options.max_clients)) {
    counters.too_many_clients++;
    return false;
  }
  sessions[s->id()] = s;
  counters.ws_opened++;
  return true;
}

void WebServer::Impl::remove_session(std::uint64_t id) {
  if (sessions.erase(id) > 0) counters.ws_closed++;
  std::lock_guard<std::mutex> lock(drive_mutex);
  arbiter.release(id);  // a closed driving page stops the commands at once
}

std::string WebServer::Impl::hello(std::uint64_t id) {
  std::lock_guard<std::mutex> lock(drive_mutex);
  nlohmann::json j;
  j["type"] = "hello";
  j["id"] = id;
  j["instrument"] = options.instrument;
  j["instrument_name"] = options.instrument_name;
  j["force_limit"] = options.force_limit;
  j["scene"] = options.scene;
  j["pose"] = {{"pitch", current.pitch}, {"yaw", current.yaw}, {"insertion", current.insertion},
               {"roll", current.roll}, {"jaw", current.jaw}};
  const DeviceLimits& l = options.limits;
  j["limits"] = {{"max_angle", l.max_angle}, {"max_insertion", l.max_insertion}, {"max_jaw", l.max_jaw},
                 {"angle_rate", l.angle_rate}, {"insertion_rate", l.insertion_rate}, {"jaw_rate", l.jaw_rate}};
  j["command_rate_hz"] = options.command_rate_hz;
  j["max_message"] = options.max_ws_message;
  return j.dump();
}

void WebServer::Impl::on_message(std::uint64_t id, const std::string& text) {
  ClientMessage m;
  std::string error;
  if (!parse_client_message(text, m, error)) {
    counters.ws_malformed++;
    return;
  }
  switch (m.type) {
    case ClientMessage::Type::kTake: {
      std::lock_guard<std::mutex> lock(drive_mutex);
      const bool was = arbiter.drives(id);
      if (!arbiter.take(id)) {
        counters.drive_refused++;
      } else if (!was) {
        target = current;  // start from where the tool is: no jump
        last_pose_ns = monotonic_ns();
      }
      break;
    }
    case ClientMessage::Type::kRelease: {
      std::lock_guard<std::mutex> lock(drive_mutex);
      arbiter.release(id);
      break;
    }
    case ClientMessage::Type::kPose: {
      std::lock_guard<std::mutex> lock(drive_mutex);
      if (!arbiter.drives(id)) {
        counters.ws_not_driver++;
        break;
      }
      counters.poses++;
      target = clamp_pose(m.pose, options.limits);
      last_pose_ns = monotonic_ns();
      break;
    }
    case ClientMessage::Type::kShown: {
      const std::uint64_t stamp = dds.render_stamp_of(m.frame);
      const std::uint64_t now = monotonic_ns();
      if (stamp != 0 && now >= stamp) {
        std::lock_guard<std::mutex> lock(delay_mutex);
        delay_us.add(static_cast<double>(now - stamp) * 1e-3);
      }
      break;
    }
  }
}

void WebServer::Impl::add_live(nlohmann::json& j) {
  const Telemetry t = dds.telemetry();
  j["force"] = t.force;
  j["force_flags"] = t.force_flags;
  j["force_received"] = t.force_received;
  j["contacts"] = t.contacts;
  j["instrument_contacts"] = t.instrument_contacts;
  j["contact_frames"] = t.contact_frames;
  j["contact_seq"] = t.contact_seq;
  j["sim_time"] = t.sim_time;
  j["haptic_visual_latency_us"] = t.haptic_visual_latency_us;
  j["visual_fps"] = t.visual_fps;
  j["frames_received"] = t.frames_received;
  j["frame_number"] = t.frame_number;
  j["tool_pose"] = {t.pose.pitch, t.pose.yaw, t.pose.insertion, t.pose.roll, t.pose.jaw};
  if (t.have_scene) {
    j["scene"] = {{"name", t.scene_name}, {"scene_hash", hex64(t.scene_hash)}, {"mesh_hash", hex64(t.mesh_hash)},
                  {"material_hash", hex64(t.material_hash)}, {"tensor_hash", hex64(t.tensor_hash)},
                  {"instruments", t.instrument_count}, {"haptic_rate_hz", t.haptic_rate_hz},
                  {"organs", t.organs}};
  }
  std::lock_guard<std::mutex> lock(drive_mutex);
  j["driver"] = arbiter.driver();
  j["command_pose"] = {current.pitch, current.yaw, current.insertion, current.roll, current.jaw};
}

std::string WebServer::Impl::stats_text() {
  const Counters& c = counters;
  nlohmann::json j;
  j["requests"] = c.requests.load();
  j["pages_served"] = c.pages.load();
  j["assets_served"] = c.assets.load();
  j["stats_served"] = c.stats.load();
  j["refused"] = {{"not_found", c.not_found.load()},          {"forbidden", c.forbidden.load()},
                  {"bad_request", c.bad_request.load()},      {"method_not_allowed", c.method_not_allowed.load()},
                  {"too_many_clients", c.too_many_clients.load()}, {"ws_oversize", c.ws_oversize.load()},
                  {"ws_malformed", c.ws_malformed.load()},    {"ws_not_driver", c.ws_not_driver.load()},
                  {"drive_refused", c.drive_refused.load()}};
  j["ws_opened"] = c.ws_opened.load();
  j["ws_closed"] = c.ws_closed.load();
  j["poses_received"] = c.poses.load();
  j["commands_sent"] = c.commands_sent.load();
  j["frames_to_pages"] = c.frames_to_pages.load();
  j["frames_replaced"] = c.frames_replaced.load();
  j["connections"] = {{"open", c.open.load()},
                      {"max", c.cap.load()},
                      {"accepted", c.accepted.load()},
                      {"closed_for_room", c.closed_for_room.load()},
                      {"request_timeouts", c.request_timeouts.load()},
                      {"accept_errors", c.accept_errors.load()}};
  {
    std::lock_guard<std::mutex> lock(delay_mutex);
    j["render_to_page_us"] = to_json(delay_us.summary());  // render -> the page displayed it, echoed back here
  }
  j["render_to_server_us"] = to_json(dds.frame_arrival_us());  // render -> the frame arrived over DDS
  add_live(j);
  return j.dump();
}

void WebServer::Impl::broadcast_frame() {
  if (auto f = dds.frame_since(last_frame)) {
    std::uint64_t number = 0;
    std::memcpy(&number, f->data() + 16, sizeof number);
    last_frame = number;
    for (auto& [id, w] : sessions) {
      if (auto s = w.lock()) s->send_frame(f);
    }
  }
}

void WebServer::Impl::on_telemetry_timer() {
  nlohmann::json j;
  j["type"] = "telemetry";
  j["t"] = static_cast<double>(monotonic_ns()) * 1e-9;
  add_live(j);
  j["commands_sent"] = counters.commands_sent.load();
  j["pages"] = sessions.size();
  auto m = std::make_shared<const std::string>(j.dump());
  for (auto& [id, w] : sessions) {
    if (auto s = w.lock()) s->send_text(m);
  }
  telemetry_timer.expires_after(std::chrono::milliseconds(50));
  telemetry_timer.async_wait([this](beast::error_code ec) {
    if (!ec) on_telemetry_timer();
  });
}

void WebServer::Impl::command_loop() {
  // Fixed rate on absolute deadlines; a command only while a page drives and has spoken recently.
  const auto period = std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 / options.command_rate_hz));
  const double dt = 1.0 / options.command_rate_hz;
  const auto silence = static_cast<std::uint64_t>(options.driver_silence_s * 1e9);
  auto next = std::chrono::steady_clock::now();
  std::uint64_t seq = 0;
  while (!stopping.load()) {
    next += period;
    std::this_thread::sleep_until(next);
    if (std::chrono::steady_clock::now() - next > 10 * period) next = std::chrono::steady_clock::now();
    Pose5 pose;
    {
      std::lock_guard<std::mutex> lock(drive_mutex);
      if (arbiter.driver() == 0 || monotonic_ns() - last_pose_ns > silence) continue;
      current = step_towards(current, target, options.limits, dt);
      pose = current;
    }
    dds.publish(pose, ++seq);
    counters.commands_sent++;
  }
}

WebServer::WebServer(const ServerOptions& options, WebDds& dds) : impl_(std::make_unique<Impl>(options, dds)) {
  Impl& m = *impl_;
  for (const char* a : kAssets) m.files[a] = read_file(options.www + "/" + a);
  m.current = m.target = clamp_pose(options.start_pose, options.limits);
  beast::error_code ec;
  const auto address = net::ip::make_address(options.bind, ec);
  if (ec) throw std::runtime_error("--bind '" + options.bind + "' is not an IP address (e.g. 127.0.0.1 or 0.0.0.0)");
  const tcp::endpoint ep(address, static_cast<unsigned short>(options.port));
  m.acceptor.open(ep.protocol(), ec);
  if (!ec) m.acceptor.set_option(net::socket_base::reuse_address(true), ec);
  if (!ec) m.acceptor.bind(ep, ec);
  if (!ec) m.acceptor.listen(net::socket_base::max_listen_connections, ec);
  if (ec) {
    throw std::runtime_error("cannot listen on " + options.bind + ":" + std::to_string(options.port) + ": " +
                             ec.message() + " (choose another --port)");
  }
  m.bound_port = m.acceptor.local_endpoint().port();
  // The cap stays below the file descriptors the process may still open, so that a flood meets the cap (which
  // closes connections without the token) before accept() runs out of descriptors.
  m.min_connections = static_cast<std::size_t>(std::max(options.max_clients, 1)) + 8;
  std::size_t cap = static_cast<std::size_t>(std::max(options.max_connections, 1));
  rlimit limit{};
  if (getrlimit(RLIMIT_NOFILE, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY) {
    const std::size_t used = open_descriptors() + kDescriptorReserve;
    cap = std::min(cap, limit.rlim_cur > used ? static_cast<std::size_t>(limit.rlim_cur - used) : 0);
  }
  m.connections.set_capacity(std::max(cap, m.min_connections));
  m.counters.cap = m.connections.capacity();
}

WebServer::~WebServer() {
  impl_->stopping = true;
  if (impl_->command_thread.joinable()) impl_->command_thread.join();
}

std::string WebServer::url() const {
  const std::string host = impl_->options.bind == "0.0.0.0" ? "HOST" : impl_->options.bind;
  return "http://" + host + ":" + std::to_string(impl_->bound_port) + "/?token=" + impl_->options.token;
}

void WebServer::run(double duration) {
  Impl& m = *impl_;
  m.signals.async_wait([&m](beast::error_code, int) { m.io.stop(); });
  if (duration >= 0) {
    m.end_timer.expires_after(std::chrono::milliseconds(static_cast<std::int64_t>(duration * 1000)));
    m.end_timer.async_wait([&m](beast::error_code ec) {
      if (!ec) m.io.stop();
    });
  }
  m.command_thread = std::thread([&m] { m.command_loop(); });
  m.accept();
  // Each new frame is broadcast as soon as it arrives: the DDS thread posts the work to the I/O thread.
  m.dds.set_frame_callback([&m] { net::post(m.io, [&m] { m.broadcast_frame(); }); });
  m.on_telemetry_timer();
  m.io.run();
  m.dds.set_frame_callback(nullptr);
  m.stopping = true;
  m.command_thread.join();
}

void WebServer::stop() { impl_->io.stop(); }

nlohmann::json WebServer::stats() { return nlohmann::json::parse(impl_->stats_text()); }

}  // namespace surgsim::web
