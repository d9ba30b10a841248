// Timing statistics with storage fixed up front: recording a sample never allocates (the haptic loop uses it).
#pragma once
#include <cstddef>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

namespace surgsim::core {

struct Percentiles {
  double p50 = 0, p90 = 0, p99 = 0, max = 0, mean = 0;
  std::size_t count = 0;
};

/// A window of up to `capacity` samples for percentiles at the end: never allocates after construction (the haptic
/// loop and the multirate tracker record into it).
class SampleRecorder {
 public:
  /// Which samples the window keeps once `capacity` is reached: the first ones (a run's statistics) or the newest
  /// ones (a long-running thread's recent behaviour). count, max and mean cover every sample either way.
  enum class Keep { kFirst, kNewest };
  explicit SampleRecorder(std::size_t capacity = 1 << 20, Keep keep = Keep::kFirst);
  void add(double value) noexcept;
  std::size_t count() const { return count_; }
  Percentiles summary() const;  // allocates (a sorted copy); call outside real-time code
  /// The q-quantile (q in [0, 1]) of the samples kept, 0 without any; allocates (a sorted copy).
  double percentile(double q) const;
  void clear() noexcept;

 private:
  std::vector<double> samples_;
  Keep keep_ = Keep::kFirst;
  std::size_t stored_ = 0;
  std::size_t count_ = 0;
  double max_ = 0;
  double sum_ = 0;
};

/// {"p50":..,"p99":..,"max":..} (+ p90, mean, count) for the stats JSON.
nlohmann::json to_json(const Percentiles& p);

/// Writes a JSON value to a file atomically (temp file + rename). Throws surgsim::core::Error on failure.
void write_json_file(const std::string& path, const nlohmann::json& value);

}  // namespace surgsim::core
