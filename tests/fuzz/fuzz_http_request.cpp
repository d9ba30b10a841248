// Fuzz target: an HTTP request to surgsim-web (visual_node/web/web_request.cpp, answer_request_bytes: Beast's
// request parser with the server's limits, then the server's rules: route, token, method, upgrade), and the
// content type of the file it names.
// Expected: none. A request is answered, never thrown at, so any exception escaping is a finding (see
// fuzz_support.h).
#include "fuzz_support.h"
#include "web_request.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace surgsim::web;
  const RequestAnswer a = answer_request_bytes(surgsim::fuzz::as_text(data, size), "0123456789abcdef0123456789abcdef");
  if (a.answer == Answer::kFile) (void)content_type(a.request.route == Route::kPage ? "index.html" : a.request.asset);
  return 0;
}
