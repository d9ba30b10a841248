// The one text tokenizer of the project: trimming, splitting on a separator, whole-field numbers. Every reader of a
// line-based file or a command-line list (trajectories, curve files, NRRD headers, program options) uses these, so
// that "what counts as blank" and "what counts as a number" are the same everywhere.
//
// Numbers are parsed with std::from_chars: locale-independent and correctly rounded (the same double as strtod in the
// "C" locale), so a value read here is bit-identical to one read by any other conforming reader.
#pragma once
#include <string>
#include <string_view>
#include <vector>

namespace surgsim::core::text {

/// `s` without leading and trailing blanks (space, tab, CR, LF). No allocation.
std::string_view trim(std::string_view s) noexcept;

/// Splits on every `sep` (empty fields kept, so "a,,b" gives 3 fields and "" gives one empty field). Fields are not
/// trimmed. Views into `s`.
std::vector<std::string_view> split(std::string_view s, char sep);

/// Allocation-free split: stores up to `capacity` fields (each trimmed) in `out` and returns how many fields there
/// are in all (more than `capacity` when the line has too many).
int split_trimmed(std::string_view s, char sep, std::string_view* out, int capacity) noexcept;

/// What a whole-field number parse found.
enum class Number {
  kOk,          // a finite number spanning the whole (trimmed) field
  kNotNumber,   // empty, or not a number, or trailing characters
  kOutOfRange,  // a number too large (or too small) for a double
  kNotFinite,   // "nan", "inf" or "infinity" (any case): `out` holds it, the caller decides
};

/// Parses the whole of `s` (trimmed; one leading '+' accepted) as a double into `out`.
Number parse_double(std::string_view s, double& out) noexcept;

/// Parses the whole of `s` (trimmed) as a base-10 integer; false when it is not one or does not fit.
bool parse_int(std::string_view s, long long& out) noexcept;

/// ASCII lower case.
std::string lower(std::string_view s);

/// `s` in single quotes for a message, cut to `max` characters with "..." (a long or binary line stays readable).
std::string quote(std::string_view s, std::size_t max = 60);

}  // namespace surgsim::core::text
