#include "dds_support.h"

#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastrtps/types/TypesBase.h>
#include <cstdlib>
#include <stdexcept>

namespace surgsim::dds {

using namespace eprosima::fastdds::dds;
using eprosima::fastrtps::types::ReturnCode_t;

int default_domain() {
  if (const char* env = std::getenv("SURGSIM_DOMAIN")) {
    char* end = nullptr;
    const long v = std::strtol(env, &end, 10);
    if (end != env && *end == '\0' && v >= 0 && v <= 232) return static_cast<int>(v);
    throw std::runtime_error(std::string("SURGSIM_DOMAIN='") + env + "' is not a DDS domain id (0..232)");
  }
  return 0;
}

Participant::Participant(const DdsOptions& options) {
  auto* factory = DomainParticipantFactory::get_instance();
  if (!options.profiles_file.empty() &&
      factory->load_XML_profiles_file(options.profiles_file) != ReturnCode_t::RETCODE_OK) {
    throw std::runtime_error(options.profiles_file + ": Fast DDS could not load this XML profiles file");
  }
  DomainParticipantQos qos = PARTICIPANT_QOS_DEFAULT;
  if (factory->get_participant_qos_from_profile(options.participant_profile, qos) != ReturnCode_t::RETCODE_OK) {
    throw std::runtime_error("DDS participant profile '" + options.participant_profile + "' not found in " +
                             (options.profiles_file.empty() ? std::string("the loaded profiles") : options.profiles_file));
  }
  qos.name(options.name);
  participant_ = factory->create_participant(options.domain, qos);
  if (participant_ == nullptr) {
    throw std::runtime_error("cannot create a DDS participant on domain " + std::to_string(options.domain));
  }
  publisher_ = participant_->create_publisher(PUBLISHER_QOS_DEFAULT);
  subscriber_ = participant_->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
  if (publisher_ == nullptr || subscriber_ == nullptr) throw std::runtime_error("cannot create DDS publisher/subscriber");
}

Participant::~Participant() {
  if (participant_ == nullptr) return;
  participant_->delete_contained_entities();
  DomainParticipantFactory::get_instance()->delete_participant(participant_);
}

Topic* Participant::topic(const std::string& name, TopicDataType* type) {
  auto it = topics_.find(name);
  if (it != topics_.end()) return it->second;
  TypeSupport support(type);
  if (participant_->find_type(support.get_type_name()) == nullptr) support.register_type(participant_);
  Topic* t = participant_->create_topic(name, support.get_type_name(), TOPIC_QOS_DEFAULT);
  if (t == nullptr) throw std::runtime_error("cannot create DDS topic " + name);
  topics_[name] = t;
  return t;
}

DataWriter* Participant::writer(Topic* topic, const std::string& profile, DataWriterListener* listener) {
  DataWriter* w = publisher_->create_datawriter_with_profile(topic, profile, listener);
  if (w == nullptr) {
    throw std::runtime_error("cannot create a DDS writer on " + topic->get_name() + " with profile '" + profile +
                             "' (is the profiles file loaded?)");
  }
  return w;
}

DataReader* Participant::reader(Topic* topic, const std::string& profile, DataReaderListener* listener) {
  DataReader* r = subscriber_->create_datareader_with_profile(topic, profile, listener);
  if (r == nullptr) {
    throw std::runtime_error("cannot create a DDS reader on " + topic->get_name() + " with profile '" + profile +
                             "' (is the profiles file loaded?)");
  }
  return r;
}

}  // namespace surgsim::dds
