#include "web_request.h"

#include <boost/beast/websocket/rfc6455.hpp>

namespace surgsim::web {

namespace beast = boost::beast;
namespace http = beast::http;

void limit_request_parser(RequestParser& parser) {
  parser.header_limit(8192);
  parser.body_limit(4096);
}

RequestAnswer answer_request(const beast::error_code& read_error, const http::request<http::string_body>& request,
                             std::string_view token) {
  RequestAnswer a;
  if (read_error) {
    const bool too_big = read_error == http::error::header_limit || read_error == http::error::body_limit ||
                         read_error == http::error::buffer_overflow;
    a.answer = too_big ? Answer::kTooLarge : Answer::kMalformed;
    return a;
  }
  a.version = request.version();
  a.request = parse_target(std::string_view(request.target().data(), request.target().size()));
  a.trusted = token_matches(a.request.token, token);
  if (request.method() != http::verb::get) {
    a.answer = Answer::kMethodNotAllowed;
  } else if (a.request.route == Route::kNotFound) {
    a.answer = Answer::kNotFound;
  } else if (a.request.route != Route::kAsset && !a.trusted) {
    a.answer = Answer::kForbidden;
  } else if (a.request.route == Route::kWebSocket) {
    a.answer = beast::websocket::is_upgrade(request) ? Answer::kWebSocket : Answer::kNotUpgrade;
  } else if (a.request.route == Route::kStats) {
    a.answer = Answer::kStats;
  } else {
    a.answer = Answer::kFile;
  }
  return a;
}

RequestAnswer answer_request_bytes(std::string_view bytes, std::string_view token) {
  RequestParser parser;
  limit_request_parser(parser);
  beast::error_code ec;
  // As http::read feeds a connection's parser: the bytes not taken yet, again, until the message is done.
  while (!parser.is_done()) {
    const std::size_t used = parser.put(boost::asio::buffer(bytes.data(), bytes.size()), ec);
    bytes.remove_prefix(used);
    if (ec == http::error::need_more || (!ec && used == 0)) {
      RequestAnswer a;
      a.answer = Answer::kIncomplete;
      return a;
    }
    if (ec) break;
  }
  http::request<http::string_body> request;
  if (!ec) request = parser.release();
  return answer_request(ec, request, token);
}

}  // namespace surgsim::web
