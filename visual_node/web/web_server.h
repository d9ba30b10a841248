// surgsim-web's HTTP + WebSocket server, on Boost.Beast with one I/O thread. It serves the page (three
// files of the www folder, read once at start-up), a JSON /stats, and one WebSocket per page at /ws that carries the
// newest JPEG frame (binary, sent as soon as it arrives; while a page still receives one, a newer replaces the one
// waiting, never queued), the telemetry (JSON, 20 Hz) and the page's messages (take / release the tool, the pose it
// asks for, the frame shown).
// ToolCommand is published by a thread of its own at a fixed rate while a page drives: the pose moves towards the
// page's, slew-limited; when the driving page closes or goes silent, publishing stops and the haptic node's input
// timeout zeroes the force as for a lost device.
//
// Refused and counted, never fatal: an unknown path (404), a wrong or missing token (403), a method other than GET
// (405), a malformed or oversized request (400 / 413), more than max_clients pages (503), a WebSocket message above
// max_ws_message bytes (the socket is closed with "too big"), a malformed message or a pose from a page that does not
// drive (ignored).
// Connections are bounded so that a flood of them without the token never keeps the token holder out: a
// request not complete within request_timeout_s is closed (and a refusal not read by then too); beyond
// max_connections open connections (lowered to the file descriptors the process may still open), the oldest whose
// request did not carry the token is closed (ConnectionTable); when accept() runs out of descriptors anyway, the
// cap comes down to what fits and one such connection is closed to make room, and other accept errors are retried
// after a pause that doubles up to 1 s, never at once.
#pragma once
#include <atomic>
#include <cstdint>
#include <memory>
#include <nlohmann/json_fwd.hpp>
#include <string>

#include "web_logic.h"

namespace surgsim::web {

class WebDds;

struct ServerOptions {
  std::string bind = "127.0.0.1";
  int port = 8080;                      // 0: any free port (the URL printed says which)
  std::string token;                    // required in the URL of the page, /ws and /stats
  std::string www;                      // folder with index.html, app.js, style.css
  int max_clients = 8;                  // WebSocket pages at once
  int max_connections = 256;            // open connections at once (requests being read or answered, WebSockets)
  double request_timeout_s = 2;         // a connection's whole request must arrive within this (then it is closed)
  std::size_t max_ws_message = 4096;    // bytes; a larger message from a page closes its socket
  double command_rate_hz = 200;         // ToolCommand rate while a page drives
  double driver_silence_s = 0.5;        // a driving page silent this long stops the commands (the tab is hidden)
  DeviceLimits limits;
  tool::Pose5 start_pose;  // the virtual device's pose before any page moved it
  std::uint32_t instrument = 0;
  std::string instrument_name = "tool";
  double force_limit = 8;               // N, the instrument's device limit (the page's force bar)
  std::string scene;                    // the scene this server was started for (the page shows SceneInfo's)
  bool quiet = false;
};

class WebServer {
 public:
  /// Init: reads the page's files, binds the socket (throws std::runtime_error naming the file or the address).
  WebServer(const ServerOptions& options, WebDds& dds);
  ~WebServer();
  WebServer(const WebServer&) = delete;
  WebServer& operator=(const WebServer&) = delete;

  /// The URL to open (with the token).
  std::string url() const;
  /// Serves until stop() or `duration` seconds (< 0: no limit).
  void run(double duration);
  /// Thread-safe (e.g. from a signal handler's flag watcher).
  void stop();
  /// Counters, the delay render -> page shown, the driver and the telemetry (the /stats body, and --stats).
  nlohmann::json stats();

  struct Impl;  // the sessions of web_server.cpp use it

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace surgsim::web
