// surgsim-web's answer to an HTTP request from its bytes (visual_node/web/web_request.cpp): each answer the server
// gives, from the request a browser, a script or a malformed client sends, and the parser's limits.
#include "web_request.h"

#include <gtest/gtest.h>

#include <string>

namespace surgsim::web {
namespace {

const char* const kToken = "0123456789abcdef0123456789abcdef";

std::string get(const std::string& target, const std::string& headers = "") {
  return "GET " + target + " HTTP/1.1\r\nHost: 127.0.0.1\r\n" + headers + "\r\n";
}

TEST(WebRequest, EachRouteGetsItsAnswer) {
  const std::string t = std::string("?token=") + kToken;
  const RequestAnswer page = answer_request_bytes(get("/" + t), kToken);
  EXPECT_EQ(page.answer, Answer::kFile);
  EXPECT_EQ(page.request.route, Route::kPage);
  EXPECT_TRUE(page.trusted);
  EXPECT_EQ(page.version, 11u);

  const RequestAnswer asset = answer_request_bytes("GET /app.js HTTP/1.0\r\n\r\n", kToken);
  EXPECT_EQ(asset.answer, Answer::kFile);  // the page's files need no token
  EXPECT_EQ(asset.request.asset, "app.js");
  EXPECT_FALSE(asset.trusted);
  EXPECT_EQ(asset.version, 10u);

  EXPECT_EQ(answer_request_bytes(get("/stats" + t), kToken).answer, Answer::kStats);
  const std::string upgrade =
      "Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
      "Sec-WebSocket-Version: 13\r\n";
  EXPECT_EQ(answer_request_bytes(get("/ws" + t, upgrade), kToken).answer, Answer::kWebSocket);
  EXPECT_EQ(answer_request_bytes(get("/ws" + t), kToken).answer, Answer::kNotUpgrade);
}

TEST(WebRequest, RefusalsSayWhy) {
  EXPECT_EQ(answer_request_bytes(get("/?token=wrong"), kToken).answer, Answer::kForbidden);
  EXPECT_EQ(answer_request_bytes(get("/ws"), kToken).answer, Answer::kForbidden);
  EXPECT_EQ(answer_request_bytes(get("/../etc/passwd"), kToken).answer, Answer::kNotFound);
  const RequestAnswer post =
      answer_request_bytes(std::string("POST /?token=") + kToken + " HTTP/1.1\r\nContent-Length: 2\r\n\r\nhi", kToken);
  EXPECT_EQ(post.answer, Answer::kMethodNotAllowed);
  EXPECT_TRUE(post.trusted);  // the token holder's connection is trusted whatever it then asks
  EXPECT_EQ(answer_request_bytes("hello world\r\n\r\n", kToken).answer, Answer::kMalformed);
  EXPECT_EQ(answer_request_bytes(get("/", "X-Big: " + std::string(9000, 'a') + "\r\n"), kToken).answer,
            Answer::kTooLarge);
  EXPECT_EQ(
      answer_request_bytes("POST / HTTP/1.1\r\nContent-Length: 5000\r\n\r\n" + std::string(5000, 'b'), kToken).answer,
      Answer::kTooLarge);
}

TEST(WebRequest, BytesEndingEarlyWaitForMore) {
  EXPECT_EQ(answer_request_bytes("", kToken).answer, Answer::kIncomplete);
  EXPECT_EQ(answer_request_bytes("GET / HTTP/1.1\r\nHost: x\r\n", kToken).answer, Answer::kIncomplete);
  EXPECT_EQ(answer_request_bytes("POST / HTTP/1.1\r\nContent-Length: 10\r\n\r\nabc", kToken).answer,
            Answer::kIncomplete);
}

}  // namespace
}  // namespace surgsim::web
