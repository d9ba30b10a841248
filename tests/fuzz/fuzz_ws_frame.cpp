// Fuzz target: WebSocket frames from a page to surgsim-web: Boost.Beast's server side as the server sets it up (the
// upgrade accepted, messages above ServerOptions::max_ws_message refused), over an in-memory stream whose input is
// the fuzzer's bytes, each text message then parsed as the server does (parse_client_message). Client frames are
// masked; ping, pong and close frames are answered into the stream's other end.
// Expected: none. The server reads with error codes (an error closes that page's socket), so any exception escaping
// is a finding (see fuzz_support.h).
#include <boost/beast/_experimental/test/stream.hpp>
#include <boost/beast/core/buffers_to_string.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>

#include "fuzz_support.h"
#include "web_logic.h"
#include "web_server.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace beast = boost::beast;
  namespace http = beast::http;
  namespace websocket = beast::websocket;
  using namespace surgsim::web;

  // The upgrade request as the HTTP session hands it over.
  http::request<http::string_body> upgrade{http::verb::get, "/ws?token=t", 11};
  upgrade.set(http::field::host, "127.0.0.1");
  upgrade.set(http::field::upgrade, "websocket");
  upgrade.set(http::field::connection, "Upgrade");
  upgrade.set(http::field::sec_websocket_key, "dGhlIHNhbXBsZSBub25jZQ==");
  upgrade.set(http::field::sec_websocket_version, "13");

  boost::asio::io_context io;
  beast::test::stream page(io);
  websocket::stream<beast::test::stream> ws(io);
  ws.next_layer().connect(page);
  ws.read_message_max(ServerOptions{}.max_ws_message);
  beast::error_code ec;
  ws.accept(upgrade, ec);
  if (ec) std::abort();  // a valid upgrade is always accepted: the harness is broken
  // The page's bytes, then the end of its stream.
  ws.next_layer().append(beast::string_view(reinterpret_cast<const char*>(data), size));
  ws.next_layer().close_remote();
  for (;;) {
    beast::flat_buffer buffer;
    ws.read(buffer, ec);
    if (ec) break;
    if (!ws.got_text()) continue;
    ClientMessage m;
    std::string error;
    (void)parse_client_message(beast::buffers_to_string(buffer.data()), m, error);
  }
  return 0;
}
