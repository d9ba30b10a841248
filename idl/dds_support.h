// Thin helpers over Fast DDS 2.9 so both nodes create entities the same way: one participant from an XML
// profile, topics by name, writers/readers from endpoint profiles. Construction throws std::runtime_error
// (start-up only); nothing here is called from the real-time loop except DataWriter::write on a writer it made.
#pragma once
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace surgsim::dds {

// Topic names (docs/DESIGN.md, section 'Topics').
inline constexpr const char* kToolCommandTopic = "surgsim/tool_command";
inline constexpr const char* kContactFrameTopic = "surgsim/contact_frame";
inline constexpr const char* kBodyStateTopic = "surgsim/body_state";
inline constexpr const char* kForceFeedbackTopic = "surgsim/force_feedback";
inline constexpr const char* kSceneInfoTopic = "surgsim/scene_info";
inline constexpr const char* kVisualStatusTopic = "surgsim/visual_status";

// Endpoint profiles in config/dds/profiles.xml.
inline constexpr const char* kStreamWriter = "surgsim_stream_writer";
inline constexpr const char* kStreamReader = "surgsim_stream_reader";
inline constexpr const char* kLatchedWriter = "surgsim_latched_writer";
inline constexpr const char* kLatchedReader = "surgsim_latched_reader";
inline constexpr const char* kContactWriter = "surgsim_contact_writer";  // stream + deadline + liveliness
inline constexpr const char* kContactReader = "surgsim_contact_reader";

// Environment read by Participant (see config/dds/profiles.xml).
inline constexpr const char* kParticipantEnv = "SURGSIM_DDS_PARTICIPANT";     // participant profile when none is given
inline constexpr const char* kPeersEnv = "SURGSIM_DDS_PEERS";                 // ADDR[:PORT],... initial peers
inline constexpr const char* kDiscoveryServerEnv = "SURGSIM_DISCOVERY_SERVER";  // ADDR:PORT,... (client profiles)

struct DdsOptions {
  int domain = 0;                                  // DDS domain id (0..232); $SURGSIM_DOMAIN overrides the default
  std::string profiles_file;                       // Fast DDS XML; empty = <config>/dds/profiles.xml
  std::string participant_profile;                 // empty: $SURGSIM_DDS_PARTICIPANT, else surgsim_default
  std::string name = "surgsim";                    // participant name seen in discovery
};

/// Default domain: $SURGSIM_DOMAIN when set (tests use it to isolate parallel runs), else 0.
int default_domain();

/// The participant profile to use: `requested` when not empty, else $SURGSIM_DDS_PARTICIPANT, else surgsim_default.
std::string participant_profile(const std::string& requested);

/// Parses "ADDR[:PORT][,ADDR[:PORT]...]" (IPv4 addresses or host names; port 0 when absent). Throws
/// std::runtime_error naming `what` on a malformed entry.
std::vector<std::pair<std::string, int>> parse_address_list(const std::string& text, const std::string& what);

class Participant {
 public:
  explicit Participant(const DdsOptions& options);
  ~Participant();
  Participant(const Participant&) = delete;
  Participant& operator=(const Participant&) = delete;

  /// Registers the type (once) and creates or returns the topic. Takes ownership of `type` (a new instance per call,
  /// as `new msg::XPubSubType()`): it is freed when it is not needed, also when the topic already exists.
  eprosima::fastdds::dds::Topic* topic(const std::string& name, eprosima::fastdds::dds::TopicDataType* type);
  eprosima::fastdds::dds::DataWriter* writer(eprosima::fastdds::dds::Topic* topic, const std::string& profile,
                                              eprosima::fastdds::dds::DataWriterListener* listener = nullptr);
  eprosima::fastdds::dds::DataReader* reader(eprosima::fastdds::dds::Topic* topic, const std::string& profile,
                                              eprosima::fastdds::dds::DataReaderListener* listener = nullptr);
  eprosima::fastdds::dds::DomainParticipant* get() const { return participant_; }
  /// The participant profile used and a one-line description of transport and discovery (for logs and stats).
  const std::string& profile() const { return profile_; }
  const std::string& description() const { return description_; }

 private:
  eprosima::fastdds::dds::DomainParticipant* participant_ = nullptr;
  eprosima::fastdds::dds::Publisher* publisher_ = nullptr;
  eprosima::fastdds::dds::Subscriber* subscriber_ = nullptr;
  std::map<std::string, eprosima::fastdds::dds::Topic*> topics_;
  std::string profile_;
  std::string description_;
};

}  // namespace surgsim::dds
