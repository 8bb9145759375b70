#include "quad.h"

void quad_init(quad_t *q, uint8_t ab)
{
    q->count = 0;
    q->state = ab & 3;
    q->errors = 0;
}
