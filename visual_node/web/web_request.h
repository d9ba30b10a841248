// How surgsim-web answers one HTTP request, without sockets: the limits of the parser a connection's request is read
// into, and the answer a request read (or refused by the parser) gets. web_server.cpp reads each request into a
// parser limited by limit_request_parser and answers what answer_request says; answer_request_bytes runs the same
// parser and rules over a request's bytes (the tests and the fuzz target's way in).
#pragma once
#include <boost/beast/http.hpp>
#include <string_view>

#include "web_logic.h"

namespace surgsim::web {

/// What the server does with a request.
enum class Answer {
  kTooLarge,          // 413: the header or the body is above the limits
  kMalformed,         // 400: not an HTTP request the parser accepts
  kMethodNotAllowed,  // 405: a method other than GET
  kNotFound,          // 404: a path that is not the page's
  kForbidden,         // 403: the page, /ws or /stats without the right token
  kNotUpgrade,        // 400: /ws without a WebSocket upgrade
  kWebSocket,         // the upgrade to the page's WebSocket
  kStats,             // 200: /stats
  kFile,              // 200: one of the page's files (request.route kPage or kAsset)
  kIncomplete,        // (answer_request_bytes only) the bytes end before the request does: the server waits for more
};

struct RequestAnswer {
  Answer answer = Answer::kMalformed;
  Request request;        // the target's route, asset and token (when the request was read)
  bool trusted = false;   // the request carried the server's token
  unsigned version = 11;  // the HTTP version to answer with (the request's, or 1.1 when it was refused unread)
};

using RequestParser = boost::beast::http::request_parser<boost::beast::http::string_body>;

/// The limits of a request: 8 KiB of header, 4 KiB of body.
void limit_request_parser(RequestParser& parser);

/// The answer to a request: `read_error` is the parser's error (then `request` is not looked at: too large or
/// malformed), else `request` is the request read. `token` is the server's.
RequestAnswer answer_request(const boost::beast::error_code& read_error,
                             const boost::beast::http::request<boost::beast::http::string_body>& request,
                             std::string_view token);

/// The same for a request's bytes, put through a parser limited as a connection's is. Never throws.
RequestAnswer answer_request_bytes(std::string_view bytes, std::string_view token);

}  // namespace surgsim::web
