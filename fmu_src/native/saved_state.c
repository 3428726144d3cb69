/* FMU states in bytes (model.h, SavedState): the serialized form both FMI layers use for
 * fmi2SerializeFMUstate / fmi3SerializeFMUState, with the layer's mark so that one layer's
 * state is refused by the other.  It needs only sizeof(ModelState) and the model's
 * model_check_state, so the mechanisms' FMUs (state_check.c) and the components' (block/block.c)
 * compile the same file, and a build replacing model.c (the benchmark's floor model) keeps it.
 *
 * A serialized state comes from outside (a file, another process): its bytes are checked field
 * by field (model_check_state) before an instance may use them.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "model.h"

typedef struct {
    char magic[8];
    unsigned int state_size;
    char guid[48];
    int model_exchange;
} StateHeader;

size_t model_serialized_size(void)
{
    return sizeof(StateHeader) + sizeof(ModelState);
}

void model_serialize(const SavedState *saved, const char magic[8], unsigned char *bytes)
{
    StateHeader header;
    memset(&header, 0, sizeof header);
    memcpy(header.magic, magic, sizeof header.magic);
    header.state_size = (unsigned int)sizeof(ModelState);
    strncpy(header.guid, FMU_GUID, sizeof header.guid - 1);
    header.model_exchange = saved->model_exchange;
    memcpy(bytes, &header, sizeof header);
    memcpy(bytes + sizeof header, &saved->state, sizeof(ModelState));
}

int model_deserialize(const unsigned char *bytes, size_t size, const char magic[8], SavedState *saved, char *why,
                      size_t n)
{
    StateHeader header;
    SavedState read;
    if (n > 0) why[0] = '\0';
    if (size != model_serialized_size()) return MODEL_WRONG_SIZE;
    memcpy(&header, bytes, sizeof header);
    if (memcmp(header.magic, magic, sizeof header.magic) != 0 || header.state_size != sizeof(ModelState)
        || strncmp(header.guid, FMU_GUID, sizeof header.guid) != 0
        || (header.model_exchange != 0 && header.model_exchange != 1))
        return MODEL_NOT_OURS;
    memcpy(&read.state, bytes + sizeof header, sizeof(ModelState));
    read.model_exchange = header.model_exchange;
    if (model_check_state(&read.state, read.model_exchange, why, n)) return MODEL_INVALID;
    *saved = read;
    return 0;
}
