#include "dds_write_spy.h"

#include <dlfcn.h>

#include <atomic>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <mutex>

#include "surgsim_types.h"
#include "dds_support.h"

namespace surgsim::test {
namespace {
std::mutex g_mutex;
std::atomic<bool> g_on{false};
std::vector<DdsWrite> g_writes;
}  // namespace

void dds_spy_start() {
  std::lock_guard<std::mutex> lock(g_mutex);
  g_writes.clear();
  g_on.store(true);
}

std::vector<DdsWrite> dds_spy_stop() {
  g_on.store(false);
  std::lock_guard<std::mutex> lock(g_mutex);
  return g_writes;
}

}  // namespace surgsim::test

namespace eprosima::fastdds::dds {

// Interposes libfastrtps's DataWriter::write(void*) (symbol version CODEABI_1.0 in Fast DDS 2.9).
bool DataWriter::write(void* data) {
  using Real = bool (*)(DataWriter*, void*);
  static const Real real = [] {
    void* f = dlvsym(RTLD_NEXT, "_ZN8eprosima7fastdds3dds10DataWriter5writeEPv", "CODEABI_1.0");
    if (f == nullptr) f = dlsym(RTLD_NEXT, "_ZN8eprosima7fastdds3dds10DataWriter5writeEPv");
    return reinterpret_cast<Real>(f);
  }();
  if (surgsim::test::g_on.load()) {
    surgsim::test::DdsWrite w;
    w.thread = std::this_thread::get_id();
    w.topic = get_topic()->get_name();
    if (w.topic == surgsim::dds::kForceFeedbackTopic) {
      const auto* f = static_cast<const surgsim::msg::ForceFeedback*>(data);
      w.seq = f->seq();
      w.instrument = static_cast<int>(f->instrument());
      w.force[0] = f->force().x();
      w.force[1] = f->force().y();
      w.force[2] = f->force().z();
      w.flags = f->flags();
    } else if (w.topic == surgsim::dds::kContactFrameTopic) {
      const auto* c = static_cast<const surgsim::msg::ContactFrame*>(data);
      w.seq = c->seq();
      w.flags = c->flags();
      for (const surgsim::msg::ContactEntry& e : c->contacts()) {
        w.contact_organs.push_back(static_cast<int>(e.organ()));
        w.contact_nodes.push_back(static_cast<int>(e.node()));
      }
    } else if (w.topic == surgsim::dds::kBodyStateTopic) {
      const auto* b = static_cast<const surgsim::msg::BodyState*>(data);
      w.seq = b->seq();
      w.organ = static_cast<int>(b->organ());
    } else if (w.topic == surgsim::dds::kSceneInfoTopic) {
      const auto* s = static_cast<const surgsim::msg::SceneInfo*>(data);
      w.scene_name = s->scene_name();
      w.mesh_hash = s->mesh_hash();
      w.tensor_hash = s->tensor_hash();
      w.node_count = s->node_count();
      w.surface_node_count = s->surface_node_count();
      for (const surgsim::msg::OrganInfo& o : s->organs()) {
        surgsim::test::OrganInfoWrite x;
        x.name = o.name();
        x.model = o.model();
        x.mesh_hash = o.mesh_hash();
        x.tensor_hash = o.tensor_hash();
        x.node_count = o.node_count();
        x.surface_node_count = o.surface_node_count();
        w.organs.push_back(x);
      }
    }
    std::lock_guard<std::mutex> lock(surgsim::test::g_mutex);
    surgsim::test::g_writes.push_back(w);
  }
  return real(this, data);
}

}  // namespace eprosima::fastdds::dds
