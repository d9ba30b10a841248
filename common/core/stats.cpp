#include "core/stats.h"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>

#include "core/error.h"

namespace surgsim::core {

namespace {
// The q-quantile of sorted, non-empty values: the nearest rank.
double quantile(const std::vector<double>& sorted, double q) {
  const double clamped = std::clamp(q, 0.0, 1.0);
  return sorted[std::min(sorted.size() - 1,
                         static_cast<std::size_t>(clamped * static_cast<double>(sorted.size() - 1) + 0.5))];
}
}  // namespace

SampleRecorder::SampleRecorder(std::size_t capacity, Keep keep) : samples_(capacity, 0.0), keep_(keep) {}

void SampleRecorder::add(double value) noexcept {
  if (stored_ < samples_.size()) {
    samples_[stored_++] = value;
  } else if (keep_ == Keep::kNewest && !samples_.empty()) {
    samples_[count_ % samples_.size()] = value;  // the oldest kept sample (the window is full)
  }
  if (count_ == 0 || value > max_) max_ = value;
  sum_ += value;
  ++count_;
}

void SampleRecorder::clear() noexcept {
  stored_ = count_ = 0;
  max_ = sum_ = 0;
}

Percentiles SampleRecorder::summary() const {
  Percentiles p;
  p.count = count_;
  if (stored_ == 0) return p;
  std::vector<double> v(samples_.begin(), samples_.begin() + static_cast<std::ptrdiff_t>(stored_));
  std::sort(v.begin(), v.end());
  p.p50 = quantile(v, 0.50);
  p.p90 = quantile(v, 0.90);
  p.p99 = quantile(v, 0.99);
  p.max = max_;
  p.mean = sum_ / static_cast<double>(count_);
  return p;
}

double SampleRecorder::percentile(double q) const {
  if (stored_ == 0) return 0;
  std::vector<double> v(samples_.begin(), samples_.begin() + static_cast<std::ptrdiff_t>(stored_));
  std::sort(v.begin(), v.end());
  return quantile(v, q);
}

nlohmann::json to_json(const Percentiles& p) {
  return nlohmann::json{{"p50", p.p50}, {"p90", p.p90}, {"p99", p.p99}, {"max", p.max}, {"mean", p.mean},
                        {"count", p.count}};
}

void write_json_file(const std::string& path, const nlohmann::json& value) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp);
    if (!out) throw_error(path, ": cannot create the stats file (check that its folder exists and is writable)");
    out << value.dump(2) << "\n";
    if (!out) throw_error(path, ": write failed");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) throw_error(path, ": cannot rename ", tmp, " into place");
}

}  // namespace surgsim::core
